//! The layout the user guide's source map (docs/src/reference/layout.md) draws is the one the
//! compiler sees: in each crate of
//! the workspace the top-level modules use each other without cycles (data flows one way),
//! and the numerical core names nothing of the service.
//!
//! A module's uses are read from its source text: every `crate::NAME` outside comments and
//! tests (a test may use anything), and `super::NAME` in a top-level file (where `super` is
//! the crate root). Cross-module paths are written that way in this workspace, so nothing
//! hides from the check.
//!
//! Inside the core's modules the same holds file by file: the files of `solve/`, of
//! `linalg/`, … use each other without cycles ([`core_files_form_no_cycle`]), with every
//! `crate::`, `super::` and `self::` path (and its `{…}` groups) resolved to the file that
//! defines it.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

type Graph = BTreeMap<String, BTreeSet<String>>;

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// Identifiers following `prefix` in `line`.
fn names_after<'a>(line: &'a str, prefix: &'a str) -> impl Iterator<Item = &'a str> + 'a {
    line.match_indices(prefix).filter_map(move |(i, _)| {
        let before = line[..i].chars().next_back();
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
            return None;
        }
        let rest = &line[i + prefix.len()..];
        let end = rest
            .find(|c: char| !(c.is_alphanumeric() || c == '_'))
            .unwrap_or(rest.len());
        (end > 0).then(|| &rest[..end])
    })
}

/// The top-level module a file below `src` belongs to.
fn top_module(rel: &Path) -> String {
    let first = rel.components().next().unwrap().as_os_str();
    first.to_str().unwrap().trim_end_matches(".rs").to_string()
}

/// Top-level module → the top-level modules of the same crate it uses.
fn module_graph(src: &Path) -> Graph {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    let modules: BTreeSet<String> = files
        .iter()
        .map(|f| top_module(f.strip_prefix(src).unwrap()))
        .collect();
    let mut graph = Graph::new();
    for f in &files {
        let rel = f.strip_prefix(src).unwrap();
        let top_level_file = rel.components().count() == 1;
        let module = top_module(rel);
        if module == "lib" || module == "main" || f.ends_with("tests.rs") {
            continue;
        }
        let text = code_of(&std::fs::read_to_string(f).unwrap());
        for code in text.lines() {
            let mut used: Vec<&str> = names_after(code, "crate::").collect();
            if top_level_file {
                used.extend(names_after(code, "super::"));
            }
            for u in used {
                if u != module && modules.contains(u) {
                    graph
                        .entry(module.clone())
                        .or_default()
                        .insert(u.to_string());
                }
            }
        }
    }
    graph
}

/// A cycle of `graph`, if it has one.
fn find_cycle(graph: &Graph) -> Option<Vec<String>> {
    fn visit(
        g: &Graph,
        m: &str,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(i) = path.iter().position(|p| p == m) {
            let mut cycle = path[i..].to_vec();
            cycle.push(m.to_string());
            return Some(cycle);
        }
        if done.contains(m) {
            return None;
        }
        path.push(m.to_string());
        for n in g.get(m).into_iter().flatten() {
            if let Some(c) = visit(g, n, path, done) {
                return Some(c);
            }
        }
        path.pop();
        done.insert(m.to_string());
        None
    }
    let mut done = BTreeSet::new();
    graph
        .keys()
        .find_map(|m| visit(graph, m, &mut Vec::new(), &mut done))
}

#[test]
fn the_cycle_finder_finds_cycles() {
    let g: Graph = [("a", "b"), ("b", "c"), ("c", "a")]
        .into_iter()
        .map(|(x, y)| (x.to_string(), BTreeSet::from([y.to_string()])))
        .collect();
    assert_eq!(find_cycle(&g).unwrap().len(), 4);
    let mut acyclic = g.clone();
    acyclic.remove("c");
    assert_eq!(find_cycle(&acyclic), None);
}

#[test]
fn core_modules_form_no_cycle() {
    let g = module_graph(&workspace().join("crates/contact-core/src"));
    // The data flow of the guide's diagram, spot-checked in both directions.
    for (from, to) in [
        ("problem", "expr"),
        ("scene", "problem"),
        ("output", "solve"),
        ("run", "output"),
        ("study", "run"),
    ] {
        assert!(
            g[from].contains(to),
            "{from} is expected to use {to}: {g:?}"
        );
        assert!(
            !g.get(to).is_some_and(|s| s.contains(from)),
            "{to} uses {from}"
        );
    }
    assert_eq!(find_cycle(&g), None, "module graph: {g:?}");
}

#[test]
fn service_modules_form_no_cycle() {
    let g = module_graph(&workspace().join("src"));
    assert!(g["routes"].contains("state") && g["app"].contains("routes"));
    assert_eq!(find_cycle(&g), None, "module graph: {g:?}");
}

#[test]
fn the_core_names_nothing_of_the_service() {
    let mut files = Vec::new();
    rust_files(&workspace().join("crates/contact-core"), &mut files);
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap();
        for word in [
            "contact_sim::",
            "axum::",
            "tokio::",
            "rusqlite::",
            "postgres::",
        ] {
            assert!(!text.contains(word), "{} mentions {word}", f.display());
        }
    }
}

/// The first code block of the guide's source layout: one line per module, its path first.
fn layout_map() -> Vec<String> {
    let text = std::fs::read_to_string(workspace().join("docs/src/reference/layout.md")).unwrap();
    let block = text.split("```").nth(1).expect("a code block");
    block
        .lines()
        .filter_map(|l| l.split_whitespace().next())
        .map(str::to_string)
        .collect()
}

#[test]
fn layout_map_names_every_module_file_and_no_other() {
    let listed = layout_map();
    let mut files = Vec::new();
    for dir in ["src", "crates/contact-core/src"] {
        rust_files(&workspace().join(dir), &mut files);
    }
    // A module's sibling tests.rs goes with its module's line.
    for f in files.iter().filter(|f| !f.ends_with("tests.rs")) {
        let rel = f.strip_prefix(workspace()).unwrap().to_str().unwrap();
        // A directory's line stands for its mod.rs.
        let as_listed = match rel.strip_suffix("mod.rs") {
            Some(dir) => dir.to_string(),
            None => rel.to_string(),
        };
        assert!(
            listed.contains(&as_listed),
            "docs/src/reference/layout.md does not list {as_listed}"
        );
    }
    for l in listed.iter().filter(|l| l.contains('/')) {
        assert!(
            workspace().join(l).exists(),
            "docs/src/reference/layout.md lists {l}, which does not exist"
        );
    }
}

/// A file's module path below `src`: `solve/velocity.rs` → [solve, velocity]; a `mod.rs`
/// stands for its directory.
fn file_module(rel: &Path) -> Vec<String> {
    let mut parts: Vec<String> = rel
        .components()
        .map(|c| c.as_os_str().to_str().unwrap().to_string())
        .collect();
    let last = parts.pop().unwrap();
    let stem = last.trim_end_matches(".rs");
    if stem != "mod" && stem != "lib" {
        parts.push(stem.to_string());
    }
    parts
}

/// The code of a file: comments removed, and nothing from its inline test module on (tests
/// may use anything).
fn code_of(text: &str) -> String {
    let lines: Vec<&str> = text.lines().collect();
    let end = (0..lines.len())
        .find(|&i| {
            lines[i].trim() == "#[cfg(test)]"
                && lines
                    .get(i + 1)
                    .is_some_and(|l| l.trim_start().starts_with("mod tests"))
        })
        .unwrap_or(lines.len());
    lines[..end]
        .iter()
        .map(|l| l.split("//").next().unwrap())
        .collect::<Vec<_>>()
        .join("\n")
}

/// The paths of a use tree starting at `s[*i]` (after a `::`): `a::b`, `a::{b, c::d}`,
/// `a::*`, each appended to `prefix`.
fn use_tree(s: &[char], i: &mut usize, mut prefix: Vec<String>, out: &mut Vec<Vec<String>>) {
    let skip_space = |i: &mut usize| {
        while *i < s.len() && s[*i].is_whitespace() {
            *i += 1;
        }
    };
    loop {
        skip_space(i);
        if *i < s.len() && s[*i] == '{' {
            *i += 1;
            loop {
                skip_space(i);
                if *i >= s.len() || s[*i] == '}' {
                    *i += 1;
                    return;
                }
                use_tree(s, i, prefix.clone(), out);
                // Past `as NAME` to the next item.
                while *i < s.len() && s[*i] != ',' && s[*i] != '}' {
                    *i += 1;
                }
                if *i < s.len() && s[*i] == ',' {
                    *i += 1;
                }
            }
        }
        let start = *i;
        while *i < s.len() && (s[*i].is_alphanumeric() || s[*i] == '_') {
            *i += 1;
        }
        if *i > start {
            prefix.push(s[start..*i].iter().collect());
            if s.get(*i) == Some(&':') && s.get(*i + 1) == Some(&':') {
                *i += 2;
                continue;
            }
        }
        out.push(prefix);
        return;
    }
}

/// Every path the code names from `crate::`, `super::` or `self::`, from the crate root
/// (`module`: the module of the file the code is in).
fn named_paths(code: &str, module: &[String]) -> Vec<Vec<String>> {
    let s: Vec<char> = code.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < s.len() {
        let ident_before =
            i > 0 && (s[i - 1].is_alphanumeric() || s[i - 1] == '_' || s[i - 1] == ':');
        let rest: String = s[i..s.len().min(i + 7)].iter().collect();
        let root = ["crate::", "super::", "self::"]
            .into_iter()
            .find(|r| rest.starts_with(r));
        let Some(root) = root.filter(|_| !ident_before) else {
            i += 1;
            continue;
        };
        let mut paths = Vec::new();
        let mut j = i + root.len();
        let start: Vec<String> = match root {
            "crate::" => Vec::new(),
            "super::" => module[..module.len().saturating_sub(1)].to_vec(),
            _ => module.to_vec(),
        };
        use_tree(&s, &mut j, start, &mut paths);
        for mut p in paths {
            // `super::super::x`, `x::{self, y}`.
            let mut resolved = Vec::new();
            for seg in p.drain(..) {
                match seg.as_str() {
                    "super" => {
                        resolved.pop();
                    }
                    "self" => {}
                    _ => resolved.push(seg),
                }
            }
            out.push(resolved);
        }
        i = j.max(i + 1);
    }
    out
}

/// File → the files of the same top-level module it uses, for the core. A directory's
/// `mod.rs` is the face of its files: its uses of its own files do not count, and a name it
/// re-exports (`pub use file::Name`) resolves to the file that defines it.
fn file_graph(src: &Path) -> Graph {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    let modules: BTreeMap<Vec<String>, PathBuf> = files
        .iter()
        .map(|f| (file_module(f.strip_prefix(src).unwrap()), f.clone()))
        .collect();
    let mut reexports: BTreeMap<Vec<String>, BTreeMap<String, Vec<String>>> = BTreeMap::new();
    for (m, f) in modules.iter().filter(|(_, f)| f.ends_with("mod.rs")) {
        let code = code_of(&std::fs::read_to_string(f).unwrap());
        for (at, _) in code.match_indices("pub use ") {
            let s: Vec<char> = code[at + "pub use ".len()..].chars().collect();
            let mut paths = Vec::new();
            use_tree(&s, &mut 0, Vec::new(), &mut paths);
            for p in paths.into_iter().filter(|p| p.len() >= 2) {
                let child = [m.clone(), vec![p[0].clone()]].concat();
                if modules.contains_key(&child) {
                    let name = p.last().unwrap().clone();
                    reexports.entry(m.clone()).or_default().insert(name, child);
                }
            }
        }
    }
    let resolve = |path: &[String]| -> Option<Vec<String>> {
        let n = (0..=path.len())
            .rev()
            .find(|&n| modules.contains_key(&path[..n]))?;
        let file = path[..n].to_vec();
        let via = path
            .get(n)
            .and_then(|name| reexports.get(&file).and_then(|r| r.get(name)));
        Some(via.cloned().unwrap_or(file))
    };
    let mut graph = Graph::new();
    for (m, f) in &modules {
        if m.is_empty() || f.ends_with("tests.rs") {
            continue;
        }
        let code = code_of(&std::fs::read_to_string(f).unwrap());
        for path in named_paths(&code, m) {
            let Some(used) = resolve(&path) else { continue };
            let inside = used.len() >= m.len() && used[..m.len()] == m[..];
            if used.is_empty() || used[0] != m[0] || inside {
                continue;
            }
            graph.entry(m.join("/")).or_default().insert(used.join("/"));
        }
    }
    graph
}

#[test]
fn the_file_graph_reads_groups_and_relative_paths() {
    let module = ["solve".to_string(), "velocity".to_string()];
    let code = code_of(
        "use super::{friction_node::{self, node}, SolveError};\n\
         use crate::linalg::multigrid::truncated::{Jacobian as J, Truncated};\n\
         // use super::damage;\n\
         let x = super::super::memory::human(1);\n\
         #[cfg(test)]\nmod tests {\n    use crate::run;\n}\n",
    );
    let paths: BTreeSet<String> = named_paths(&code, &module)
        .into_iter()
        .map(|p| p.join("/"))
        .collect();
    let expected = [
        "solve/friction_node",
        "solve/friction_node/node",
        "solve/SolveError",
        "linalg/multigrid/truncated/Jacobian",
        "linalg/multigrid/truncated/Truncated",
        "memory/human",
    ];
    assert_eq!(paths, expected.iter().map(|s| s.to_string()).collect());
}

#[test]
fn core_files_form_no_cycle() {
    let g = file_graph(&workspace().join("crates/contact-core/src"));
    // Spot checks that the reading sees the files' uses: a sibling, a re-export, a parent.
    for (from, to) in [
        ("solve/velocity", "solve/friction_node"),
        ("linalg/multigrid/smoother", "linalg/csr"),
        ("linalg/multigrid/smoother", "linalg/multigrid"),
    ] {
        assert!(
            g.get(from).is_some_and(|s| s.contains(to)),
            "{from} is expected to use {to}: {g:?}"
        );
    }
    assert_eq!(find_cycle(&g), None, "file graph: {g:?}");
}
