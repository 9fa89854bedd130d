//! The user guide is tested.
//!
//! - Every ` ```console ` block of `README.md` and `docs/*.md` runs (trycmd): each `$ ` line is
//!   a command, the lines after it its expected output (stdout and stderr together; `[..]`
//!   stands for any text within a line, a line `...` for any lines) and `? failed` its expected
//!   exit. `host` is this commit's binary, `cargo` the cargo running the test. The commands
//!   run in a scratch directory that holds the repository's top-level files and folders as
//!   symbolic links, so that they read the repository's paths as the guide writes them and
//!   whatever they write stays out of the tree. ` ```sh ` blocks are not run.
//! - Every `host ...` and `cargo run ... -p host -- ...` line of the ` ```sh ` blocks parses
//!   with the CLI's own parser (the binary with `HOST_PARSE_ONLY` set parses and exits), so a
//!   renamed subcommand or flag fails here until the guide follows it.
//! - Every relative link and every repository path written in backticks exists, so a file
//!   renamed or removed fails here until the guide follows it.
//! - `docs/demo.png` is of today's shipped scene: `docs/demo.png.sha256`, written by
//!   `scripts/demo-screenshot.sh` with the picture, still matches the scene and its meshes.

use std::path::{Path, PathBuf};
use std::process::Command;
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
    let text = "see `host/haptic/src/bank.rs`, `scripts/x.sh`: and ` ```console ` or `host` \
                `host/meshes/generated/a.msh` `a/b` `host/data/{a,b}.csv` [c](../x.md#y) \
                [d](https://e.org/f)";
    let spans = code_spans(text);
    let paths: Vec<&str> = spans
        .iter()
        .filter_map(|s| repository_path(s, &top))
        .collect();
    assert_eq!(paths, ["host/haptic/src/bank.rs", "scripts/x.sh"]);
    assert_eq!(link_targets(text), ["../x.md"]);
}

/// The commands of the ` ```sh ` blocks: `\\`-continued lines joined, `# comments` dropped,
/// comment-only lines left out.
fn sh_commands(text: &str) -> Vec<String> {
    let mut commands = Vec::new();
    let mut in_sh = false;
    let mut pending = String::new();
    for line in text.lines() {
        let fence = line.trim_start();
        if let Some(info) = fence.strip_prefix("```") {
            in_sh = !in_sh && info.trim() == "sh";
            continue;
        }
        if !in_sh {
            continue;
        }
        let code = match line.find(" #") {
            Some(at) => &line[..at],
            None if line.trim_start().starts_with('#') => "",
            None => line,
        };
        match code.trim_end().strip_suffix('\\') {
            Some(head) => pending.push_str(head),
            None => {
                pending.push_str(code);
                let command = pending.split_whitespace().collect::<Vec<_>>().join(" ");
                if !command.is_empty() {
                    commands.push(command);
                }
                pending.clear();
            }
        }
    }
    commands
}

/// The arguments after `host` of a plain `host ...` or `cargo run ... -p host -- ...` command;
/// `None` for anything else (another program, or shell syntax: pipes, `&&`, `$(...)`,
/// redirections, quotes, variable assignments).
fn host_args(command: &str) -> Option<Vec<&str>> {
    if command.contains(|c: char| "|&;$()<>'\"`*?".contains(c)) {
        return None;
    }
    let words: Vec<&str> = command.split_whitespace().collect();
    match words.as_slice() {
        ["host", rest @ ..] => Some(rest.to_vec()),
        ["cargo", "run", rest @ ..] => {
            let dashes = rest.iter().position(|w| *w == "--")?;
            let cargo_args = &rest[..dashes];
            cargo_args
                .windows(2)
                .any(|w| w == ["-p", "host"])
                .then(|| rest[dashes + 1..].to_vec())
        }
        _ => None,
    }
}

#[test]
fn every_host_command_in_the_guides_sh_blocks_parses() {
    let root = root();
    let mut checked = 0;
    let mut skipped = Vec::new();
    let mut failures = Vec::new();
    for file in guide_files() {
        let text = std::fs::read_to_string(&file).unwrap();
        let name = file.strip_prefix(&root).unwrap().display().to_string();
        for command in sh_commands(&text) {
            let Some(args) = host_args(&command) else {
                skipped.push(format!("{name}: {command}"));
                continue;
            };
            checked += 1;
            let out = Command::new(env!("CARGO_BIN_EXE_host"))
                .args(&args)
                .env("HOST_PARSE_ONLY", "1")
                .output()
                .unwrap();
            if !out.status.success() {
                failures.push(format!(
                    "{name}: {command}\n{}",
                    String::from_utf8_lossy(&out.stderr).trim_end()
                ));
            }
        }
    }
    println!(
        "{checked} host commands parsed; {} sh commands skipped (not a plain host invocation):",
        skipped.len()
    );
    for s in &skipped {
        println!("  {s}");
    }
    assert!(
        checked >= 25,
        "only {checked} host commands found in sh blocks"
    );
    assert!(
        failures.is_empty(),
        "the guide's sh blocks hold host commands the CLI rejects:\n{}",
        failures.join("\n\n")
    );
}

#[test]
fn the_sh_command_reader_sees_what_it_should() {
    let text = "```sh\n# a comment\nhost bank build a.toml -o a.bank   # atomic\n\
                cargo run --release -q -p host -- calibrate tissue --csv x.csv \\\n    --law P\n\
                (cd firmware/board && cargo build --release)\nbash scripts/test-all.sh\n```\n\
                host not-in-a-block\n```console\n$ host --help\n```\n";
    let commands = sh_commands(text);
    assert_eq!(
        commands,
        [
            "host bank build a.toml -o a.bank",
            "cargo run --release -q -p host -- calibrate tissue --csv x.csv --law P",
            "(cd firmware/board && cargo build --release)",
            "bash scripts/test-all.sh",
        ]
    );
    let args: Vec<Option<Vec<&str>>> = commands.iter().map(|c| host_args(c)).collect();
    assert_eq!(
        args,
        [
            Some(vec!["bank", "build", "a.toml", "-o", "a.bank"]),
            Some(vec!["calibrate", "tissue", "--csv", "x.csv", "--law", "P"]),
            None,
            None,
        ]
    );
    assert_eq!(host_args("cargo run -p fem -- x"), None);
    assert_eq!(host_args("HOST=1 host demo"), None);
}

#[test]
fn the_demo_screenshot_is_of_todays_shipped_scene() {
    let out = Command::new("sha256sum")
        .args(["--check", "--quiet", "docs/demo.png.sha256"])
        .current_dir(root())
        .output()
        .expect("sha256sum (coreutils) runs");
    assert!(
        out.status.success(),
        "the shipped scene or its meshes changed since docs/demo.png was taken: rerun \
         scripts/demo-screenshot.sh\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}
