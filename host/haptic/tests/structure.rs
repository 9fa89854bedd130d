//! Structure lint of the host library's sources (`host/haptic/src`), in plain Rust on the text
//! of the files:
//!
//! - every file holds at most [`MAX_CODE_LINES`] lines of code before its test module;
//! - the library's top-level modules (`scene`, `bank`, `display`, ...) import each other
//!   without a cycle.
//!
//! Lines of code are the non-blank lines that are not `//` comments (doc comments included),
//! counted up to the first `#[cfg(test)]` at the start of a line that a `mod` line follows (the
//! file's unit tests).
//!
//! The import graph has an edge `a -> b` when a file of module `a` names `crate::b` (in a `use`
//! or in a path, including `use crate::{b, c::d}`), or reaches `b` through `super::` (resolved
//! from the file's place in the tree). Only code counts: comments and doc links do not, and
//! neither do the files' test modules (test code may reach anywhere).
//!
//! Limits: it reads text, not the compiler's name resolution. `/* */` block comments and paths
//! inside string literals count as code; a `use` of a re-export counts against the module that
//! re-exports it, not the one that defines the item; macros that expand to paths are not seen;
//! inline `mod` blocks other than the test module count towards their file's module.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Most lines of code a library source file may hold before its tests.
const MAX_CODE_LINES: usize = 900;

/// The library's source directory.
fn src_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

/// Every `.rs` file under `dir`, sorted.
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut todo = vec![dir.to_path_buf()];
    while let Some(d) = todo.pop() {
        for entry in std::fs::read_dir(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display())) {
            let path = entry.expect("a directory entry").path();
            if path.is_dir() {
                todo.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                out.push(path);
            }
        }
    }
    out.sort();
    out
}

/// The file's lines before its test module (module notes).
fn library_lines(text: &str) -> Vec<&str> {
    let lines: Vec<&str> = text.lines().collect();
    let tests = (0..lines.len()).find(|&i| {
        lines[i].trim_end() == "#[cfg(test)]"
            && lines[i + 1..]
                .iter()
                .map(|l| l.trim())
                .find(|l| !l.is_empty())
                .is_some_and(|l| l.starts_with("mod ") || l.starts_with("pub mod "))
    });
    lines[..tests.unwrap_or(lines.len())].to_vec()
}

/// A line without its `//` comment (a `//` inside a string literal is taken for a comment too,
/// which only shortens the line).
fn code_of(line: &str) -> &str {
    line.find("//").map_or(line, |i| &line[..i])
}

/// Lines of code (module notes).
fn code_lines(text: &str) -> usize {
    library_lines(text)
        .iter()
        .filter(|l| !code_of(l).trim().is_empty())
        .count()
}

/// The module path of a source file relative to `src`: `bank/cache.rs` is `["bank", "cache"]`,
/// `display/mod.rs` is `["display"]`, `lib.rs` is `[]`.
fn module_path(src: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src).expect("a file under src");
    let mut parts: Vec<String> = rel
        .iter()
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    let last = parts.pop().expect("a file name");
    let stem = last.trim_end_matches(".rs");
    if stem != "mod" && stem != "lib" {
        parts.push(stem.to_string());
    }
    parts
}

/// Identifier characters.
fn ident_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

/// The identifier at the start of `s`.
fn ident(s: &str) -> &str {
    let end = s.find(|c: char| !ident_char(c)).unwrap_or(s.len());
    &s[..end]
}

/// The top-level modules that `code` (a file's code, comments removed) names, for a file of
/// module `module`.
fn imports(code: &str, module: &[String]) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let bytes = code.as_bytes();
    let starts = |i: usize| i == 0 || !ident_char(bytes[i - 1] as char);
    // `crate::x` and `crate::{x, y::z}`.
    for (i, _) in code.match_indices("crate::") {
        if !starts(i) {
            continue;
        }
        let rest = &code[i + "crate::".len()..];
        if let Some(list) = rest.strip_prefix('{') {
            let mut depth = 0usize;
            let mut first = true;
            for (k, c) in list.char_indices() {
                match c {
                    '{' => depth += 1,
                    '}' if depth == 0 => break,
                    '}' => depth -= 1,
                    ',' if depth == 0 => first = true,
                    c if first && ident_char(c) => {
                        out.insert(ident(&list[k..]).to_string());
                        first = false;
                    }
                    c if !c.is_whitespace() => first = false,
                    _ => {}
                }
            }
        } else {
            out.insert(ident(rest).to_string());
        }
    }
    // `super::` chains, resolved against the file's module path.
    for (i, _) in code.match_indices("super::") {
        if !starts(i) || code[..i].ends_with("super::") {
            continue;
        }
        let mut rest = &code[i..];
        let mut up = 0;
        while let Some(r) = rest.strip_prefix("super::") {
            up += 1;
            rest = r;
        }
        if up < module.len() {
            out.insert(module[0].clone());
        } else if up == module.len() {
            let name = ident(rest);
            if !name.is_empty() {
                out.insert(name.to_string());
            }
        }
    }
    out
}

/// The import graph between top-level modules (module notes): module -> modules it names.
fn import_graph(src: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for file in rust_files(src) {
        let module = module_path(src, &file);
        let Some(top) = module.first() else {
            continue;
        };
        let text = std::fs::read_to_string(&file).expect("a readable source file");
        let code: String = library_lines(&text)
            .iter()
            .map(|l| code_of(l))
            .collect::<Vec<_>>()
            .join("\n");
        let entry = graph.entry(top.clone()).or_default();
        entry.extend(imports(&code, &module).into_iter().filter(|m| m != top));
    }
    graph
}

/// A cycle of `graph` as the list of its modules (the first repeated at the end), if any.
fn find_cycle(graph: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    /// Depth-first search from `node`; `stack` is the current path, `done` the nodes whose
    /// every path is explored.
    fn visit(
        graph: &BTreeMap<String, BTreeSet<String>>,
        node: &str,
        stack: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(at) = stack.iter().position(|m| m == node) {
            let mut cycle = stack[at..].to_vec();
            cycle.push(node.to_string());
            return Some(cycle);
        }
        if done.contains(node) {
            return None;
        }
        stack.push(node.to_string());
        for next in graph.get(node).into_iter().flatten() {
            if let Some(c) = visit(graph, next, stack, done) {
                return Some(c);
            }
        }
        stack.pop();
        done.insert(node.to_string());
        None
    }
    let mut done = BTreeSet::new();
    graph
        .keys()
        .find_map(|start| visit(graph, start, &mut Vec::new(), &mut done))
}

#[test]
fn no_library_file_is_over_the_line_limit() {
    let src = src_dir();
    let over: Vec<String> = rust_files(&src)
        .iter()
        .filter_map(|f| {
            let n = code_lines(&std::fs::read_to_string(f).expect("a readable source file"));
            (n > MAX_CODE_LINES).then(|| format!("{}: {n} lines of code", f.display()))
        })
        .collect();
    assert!(
        over.is_empty(),
        "over {MAX_CODE_LINES} lines of code before the tests:\n{}",
        over.join("\n")
    );
}

#[test]
fn the_top_level_modules_import_each_other_without_a_cycle() {
    let graph = import_graph(&src_dir());
    // The lint sees the modules it must: the scene model and the bank stage, and the bank
    // stage's use of the scene.
    assert!(graph["bank"].contains("scene"), "{graph:?}");
    if let Some(cycle) = find_cycle(&graph) {
        panic!("import cycle: {}", cycle.join(" -> "));
    }
}

/// The lint's own parts on hand-written input.
#[test]
fn the_lint_counts_and_resolves_as_documented() {
    let text = "//! notes\n\nuse a;\n// comment\nfn f() {} // tail\n\n#[cfg(test)]\nmod tests {\n    fn g() {}\n}\n";
    assert_eq!(code_lines(text), 2);
    let module = vec!["bank".to_string(), "cache".to_string()];
    let code = "use super::sampled::X;\nuse super::super::display::Y;\nuse crate::{scene::{A, B}, fsio};\nlet x = crate::study::solve3(a);\nmy_crate::z();";
    let want: BTreeSet<String> = ["bank", "display", "scene", "fsio", "study"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    assert_eq!(imports(code, &module), want);
    let src = Path::new("/s");
    assert_eq!(
        module_path(src, Path::new("/s/display/mod.rs")),
        ["display"]
    );
    assert_eq!(
        module_path(src, Path::new("/s/lib.rs")),
        Vec::<String>::new()
    );
    let graph: BTreeMap<String, BTreeSet<String>> = [
        ("a", vec!["b"]),
        ("b", vec!["c"]),
        ("c", vec!["a"]),
        ("d", vec![]),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v.into_iter().map(String::from).collect()))
    .collect();
    assert_eq!(find_cycle(&graph).unwrap(), ["a", "b", "c", "a"]);
    let mut acyclic = graph.clone();
    acyclic.get_mut("c").unwrap().clear();
    assert_eq!(find_cycle(&acyclic), None);
}
