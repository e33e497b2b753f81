//! The layout the user guide's source map (docs/src/reference/layout.md) draws is the one the
//! compiler sees: in each crate of
//! the workspace the top-level modules use each other without cycles (data flows one way),
//! and the numerical core names nothing of the service.
//!
//! A module's uses are read from its source text: every `crate::NAME` outside comments, and
//! `super::NAME` in a top-level file (where `super` is the crate root). Cross-module paths
//! are written that way in this workspace, so nothing hides from the check.

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
        if module == "lib" || module == "main" {
            continue;
        }
        let text = std::fs::read_to_string(f).unwrap();
        for line in text.lines() {
            let code = line.split("//").next().unwrap();
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
