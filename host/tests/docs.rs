//! The user guide is tested (issue 29, item 4).
//!
//! - Every ` ```console ` block of `README.md` and `docs/*.md` runs (trycmd): each `$ ` line is
//!   a command, the lines after it its expected output (stdout and stderr together; `[..]`
//!   stands for any text within a line, a line `...` for any lines) and `? failed` its expected
//!   exit. `host` is this commit's binary, `cargo` the cargo running the test. The commands
//!   run in a scratch directory that holds the repository's top-level files and folders as
//!   symbolic links, so that they read the repository's paths as the guide writes them and
//!   whatever they write stays out of the tree. ` ```sh ` blocks are not run.
//! - Every relative link and every repository path written in backticks exists, so a file
//!   renamed or removed fails here until the guide follows it.

use std::path::{Path, PathBuf};
use std::time::Duration;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

/// `README.md` and every `docs/*.md`, sorted.
fn guide_files() -> Vec<PathBuf> {
    let root = root();
    let mut files: Vec<PathBuf> = std::fs::read_dir(root.join("docs"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    files.sort();
    files.insert(0, root.join("README.md"));
    files
}

/// The repository's top-level entries a guide path may start with (the build output and
/// git's folder are not the repository's files).
fn top_level() -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(root())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n != "target" && n != ".git")
        .collect();
    names.sort();
    names
}

#[test]
fn the_guides_console_examples_print_what_the_guide_shows() {
    let root = root();
    let scratch = Path::new(env!("CARGO_TARGET_TMPDIR")).join("docs-cwd");
    if scratch.exists() {
        std::fs::remove_dir_all(&scratch).unwrap();
    }
    std::fs::create_dir_all(&scratch).unwrap();
    for name in top_level() {
        std::os::unix::fs::symlink(root.join(&name), scratch.join(&name)).unwrap();
    }
    // trycmd runs each command in the test's working directory.
    std::env::set_current_dir(&scratch).unwrap();
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let cases = trycmd::TestCases::new();
    cases
        .register_bin("host", Path::new(env!("CARGO_BIN_EXE_host")))
        .register_bin("cargo", PathBuf::from(cargo))
        .timeout(Duration::from_secs(120))
        // A clean environment for what the commands print: no colours, no progress bars.
        .env("NO_COLOR", "1")
        .env("TERM", "dumb");
    for file in guide_files() {
        cases.case(file);
    }
}

/// `` `x` `` spans without whitespace, as the regex `` `([^`\s]+)` `` finds them.
fn code_spans(text: &str) -> Vec<&str> {
    let b = text.as_bytes();
    let mut spans = Vec::new();
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'`'
            && let Some(len) = text[i + 1..].find('`')
        {
            let inner = &text[i + 1..i + 1 + len];
            if !inner.is_empty() && !inner.chars().any(char::is_whitespace) {
                spans.push(inner);
                i += len + 2;
                continue;
            }
        }
        i += 1;
    }
    spans
}

/// The targets of `](target)` links, without their `#anchor`.
fn link_targets(text: &str) -> Vec<&str> {
    text.match_indices("](")
        .filter_map(|(at, _)| {
            let rest = &text[at + 2..];
            let end = rest.find(')')?;
            let target = rest[..end].split('#').next().unwrap();
            (!target.is_empty() && !target.contains("://") && !target.contains(' '))
                .then_some(target)
        })
        .collect()
}

/// A span that names a repository path: `a/b...` of plain path characters whose first part is
/// a top-level entry. Build outputs (`target/`, a crate's own `target/`) and the git-ignored
/// generated meshes are not the repository's.
fn repository_path<'a>(span: &'a str, top: &[String]) -> Option<&'a str> {
    let path = span.trim_end_matches([':', ',', '.']);
    let plain = path
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || "_.-/".contains(c));
    let first = path.split('/').next().unwrap();
    let skipped = path.contains("/target/") || path.starts_with("host/meshes/generated");
    (plain && path.contains('/') && top.iter().any(|t| t == first) && !skipped).then_some(path)
}

#[test]
fn every_link_and_repository_path_in_the_guide_exists() {
    let root = root();
    let top = top_level();
    let mut missing = Vec::new();
    let mut checked = 0;
    for file in guide_files() {
        let text = std::fs::read_to_string(&file).unwrap();
        let name = file.strip_prefix(&root).unwrap().display().to_string();
        let dir = file.parent().unwrap();
        for target in link_targets(&text) {
            checked += 1;
            if !dir.join(target).exists() {
                missing.push(format!("{name}: link ({target})"));
            }
        }
        for span in code_spans(&text) {
            if let Some(path) = repository_path(span, &top) {
                checked += 1;
                if !root.join(path).exists() {
                    missing.push(format!("{name}: `{path}`"));
                }
            }
        }
    }
    assert!(checked > 100, "only {checked} links and paths found");
    assert!(
        missing.is_empty(),
        "the guide names files that do not exist:\n{}",
        missing.join("\n")
    );
}

#[test]
fn the_path_check_sees_what_it_should() {
    let top = vec!["host".to_string(), "scripts".to_string()];
    let text = "see `host/src/bank.rs`, `scripts/x.sh`: and ` ```console ` or `host` \
                `host/meshes/generated/a.msh` `a/b` `host/data/{a,b}.csv` [c](../x.md#y) \
                [d](https://e.org/f)";
    let spans = code_spans(text);
    let paths: Vec<&str> = spans
        .iter()
        .filter_map(|s| repository_path(s, &top))
        .collect();
    assert_eq!(paths, ["host/src/bank.rs", "scripts/x.sh"]);
    assert_eq!(link_targets(text), ["../x.md"]);
}
