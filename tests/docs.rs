//! The documentation works as written: README is a quick start of at most 300 lines; every
//! relative link and anchor of README and of the user guide (docs/src, an mdBook) resolves;
//! every chapter is in SUMMARY.md and every entry of SUMMARY.md exists; every repository path
//! the text names exists; and the shell blocks of README's quick start and of the guide's
//! tutorials and how-to guides run, as written, against a real server (bash, curl and jq; with
//! `CI` set they must be installed, elsewhere the run is skipped with a message when they are
//! not).

mod common;

use common::server::Server;
use contact_sim::Config;
use serde_json::Value;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// README and every Markdown file of the guide.
fn documents() -> Vec<PathBuf> {
    let mut out = vec![root().join("README.md")];
    let mut stack = vec![root().join("docs/src")];
    while let Some(dir) = stack.pop() {
        for e in std::fs::read_dir(&dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "md") {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

/// The text outside fenced code blocks, with inline code spans blanked (links in code are
/// not links), line by line.
fn prose(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut fenced = false;
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            out.push(String::new());
            continue;
        }
        if fenced {
            out.push(String::new());
            continue;
        }
        let mut s = String::new();
        let mut in_code = false;
        for c in line.chars() {
            if c == '`' {
                in_code = !in_code;
                s.push(' ');
            } else {
                s.push(if in_code { ' ' } else { c });
            }
        }
        out.push(s);
    }
    out
}

/// Targets of the Markdown links `[text](target)` and images `![alt](target)` of a line.
fn link_targets(line: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = line;
    while let Some(i) = rest.find("](") {
        let after = &rest[i + 2..];
        let Some(end) = after.find(')') else { break };
        let target = after[..end].trim();
        // A link target has no blanks: "[0,1](ζ − g)" in a formula is not a link.
        if !target.is_empty() && !target.contains(char::is_whitespace) {
            out.push(target.to_string());
        }
        rest = &after[end..];
    }
    out
}

/// The anchors mdBook (and GitHub) give a file's headings: lower case, spaces to `-`, other
/// punctuation dropped.
fn anchors(text: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let mut fenced = false;
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
        }
        if fenced || !line.starts_with('#') {
            continue;
        }
        let title = line.trim_start_matches('#').trim();
        let slug: String = title
            .chars()
            .filter_map(|c| {
                if c.is_alphanumeric() || c == '-' || c == '_' {
                    Some(c.to_lowercase().next().unwrap())
                } else if c == ' ' {
                    Some('-')
                } else {
                    None
                }
            })
            .collect();
        out.insert(slug);
    }
    out
}

#[test]
fn readme_is_a_quick_start() {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let lines = readme.lines().count();
    assert!(
        lines <= 300,
        "README.md has {lines} lines; the quick start keeps to 300 (the rest belongs in docs/src)"
    );
    for section in [
        "## Set-up",
        "### By curl",
        "### In the browser",
        "### From Python",
        "## Speed at a glance",
    ] {
        assert!(
            readme.contains(section),
            "README has no {section:?} section"
        );
    }
    let cargo = std::fs::read_to_string(root().join("Cargo.toml")).unwrap();
    let version = cargo
        .lines()
        .find_map(|l| l.strip_prefix("rust-version = "))
        .expect("Cargo.toml gives rust-version")
        .trim_matches('"');
    assert!(
        readme.contains(&format!("Rust **{version} or newer**")),
        "README states the Rust version of Cargo.toml ({version})"
    );
}

#[test]
fn relative_links_and_anchors_resolve() {
    let guide = root().join("docs/src");
    let mut broken = Vec::new();
    for doc in documents() {
        let text = std::fs::read_to_string(&doc).unwrap();
        let in_book = doc.starts_with(&guide);
        for (n, line) in prose(&text).iter().enumerate() {
            for target in link_targets(line) {
                if target.contains("://") || target.starts_with("mailto:") {
                    continue;
                }
                let at = format!("{}:{}: {target}", doc.display(), n + 1);
                let (path, anchor) = match target.split_once('#') {
                    Some((p, a)) => (p, Some(a)),
                    None => (target.as_str(), None),
                };
                let file = if path.is_empty() {
                    doc.clone()
                } else {
                    doc.parent().unwrap().join(path)
                };
                let Ok(file) = file.canonicalize() else {
                    broken.push(format!("{at}: no such file"));
                    continue;
                };
                // The book is published on its own: its links stay inside docs/src.
                if in_book && !file.starts_with(guide.canonicalize().unwrap()) {
                    broken.push(format!("{at}: leaves the book (docs/src)"));
                    continue;
                }
                if let Some(anchor) = anchor {
                    let target_text = std::fs::read_to_string(&file).unwrap_or_default();
                    if !anchors(&target_text).contains(anchor) {
                        broken.push(format!("{at}: no heading with this anchor"));
                    }
                }
            }
        }
    }
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
}

#[test]
fn summary_lists_every_chapter() {
    let src = root().join("docs/src");
    let summary = std::fs::read_to_string(src.join("SUMMARY.md")).unwrap();
    let listed: BTreeSet<PathBuf> = summary
        .lines()
        .flat_map(link_targets)
        .map(|t| src.join(t))
        .collect();
    for p in &listed {
        assert!(
            p.is_file(),
            "SUMMARY.md lists {} which does not exist",
            p.display()
        );
    }
    for doc in documents().into_iter().filter(|d| d.starts_with(&src)) {
        if doc.file_name().unwrap() == "SUMMARY.md" {
            continue;
        }
        assert!(
            listed.contains(&doc),
            "{} is not in docs/src/SUMMARY.md",
            doc.display()
        );
    }
    assert!(root().join("docs/book.toml").is_file());
}

/// Words that look like repository paths (`dir/file.ext`).
fn path_words(text: &str) -> Vec<String> {
    const EXT: &[&str] = &[
        "rs", "py", "md", "json", "yaml", "toml", "sh", "js", "mjs", "msh", "png", "svg",
    ];
    let mut out = Vec::new();
    for word in text.split(|c: char| {
        c.is_whitespace()
            || matches!(
                c,
                '`' | '(' | ')' | '[' | ']' | ',' | ';' | '"' | '\'' | '<' | '>' | '*' | '='
            )
    }) {
        // curl's `--data-binary @file` names a file too.
        let w = word.trim_end_matches(['.', ':']).trim_start_matches('@');
        let Some((stem, ext)) = w.rsplit_once('.') else {
            continue;
        };
        if !stem.contains('/') || !EXT.contains(&ext) || w.contains("://") || w.contains('$') {
            continue;
        }
        // Placeholders (DIR/summary.json, DATA_DIR/...), absolute paths and URL paths are
        // not repository paths.
        let first = w.split('/').next().unwrap();
        if first.is_empty() || first.chars().all(|c| c.is_ascii_uppercase() || c == '_') {
            continue;
        }
        out.push(w.to_string());
    }
    out
}

/// The repository's top-level folders.
const ROOT_DIRS: &[&str] = &[
    "src", "tests", "benches", "crates", "api", "clients", "docs", ".ci",
];

#[test]
fn named_paths_exist() {
    // A path is named from the repository root, or (in the numerics chapter and the layout)
    // relative to the core crate's sources or the Python client, or to the document.
    let r = root();
    let bases = [
        r.join("crates/contact-core/src"),
        r.join("crates/contact-core/tests"),
        r.join("clients/python"),
    ];
    let mut stale = Vec::new();
    for doc in documents() {
        let text = std::fs::read_to_string(&doc).unwrap();
        for (n, line) in text.lines().enumerate() {
            for w in path_words(line) {
                let here = doc.parent().unwrap().join(&w);
                // A path that starts like a top-level folder is read from the root only
                // (`src/solve/...` is not the core's `crates/contact-core/src/solve/...`).
                let first = w.split('/').next().unwrap();
                let found = if ROOT_DIRS.contains(&first) {
                    r.join(&w).exists()
                } else {
                    here.exists() || bases.iter().any(|b| b.join(&w).exists())
                };
                if found {
                    continue;
                }
                stale.push(format!("{}:{}: {w}", doc.display(), n + 1));
            }
        }
    }
    assert!(
        stale.is_empty(),
        "paths named in the docs that do not exist:\n{}",
        stale.join("\n")
    );
}

/// A ```sh block of the guide and the output it shows: the ```text block that follows it
/// with only blank lines between, if any.
struct Block {
    code: String,
    expected: Option<String>,
}

/// The ```sh blocks of a Markdown text, in order, with the output each shows; with
/// `section`, only those under that heading (up to the next heading of the same or a higher
/// level).
fn blocks(text: &str, section: Option<&str>) -> Vec<Block> {
    let mut blocks: Vec<Block> = Vec::new();
    let mut inside = section.is_none();
    let level = section.map_or(0, |s| s.chars().take_while(|&c| c == '#').count());
    // The fence being read: its language and text so far.
    let mut current: Option<(&str, String)> = None;
    // Whether the last thing read was a shell block (blank lines aside).
    let mut after_shell = false;
    for line in text.lines() {
        if let Some((_, b)) = current.as_mut() {
            if line.trim_start().starts_with("```") {
                let (lang, b) = current.take().unwrap();
                match lang {
                    "sh" => {
                        blocks.push(Block {
                            code: b,
                            expected: None,
                        });
                        after_shell = true;
                        continue;
                    }
                    "text" if after_shell => blocks.last_mut().unwrap().expected = Some(b),
                    _ => {}
                }
                after_shell = false;
            } else {
                b.push_str(line);
                b.push('\n');
            }
            continue;
        }
        if line.trim().is_empty() {
            continue;
        }
        if line.starts_with('#') {
            let l = line.chars().take_while(|&c| c == '#').count();
            if Some(line.trim_end()) == section {
                inside = true;
            } else if section.is_some() && l <= level {
                inside = false;
            }
        }
        match line.trim_start() {
            "```sh" if inside => current = Some(("sh", String::new())),
            "```text" if inside => current = Some(("text", String::new())),
            l if l.starts_with("```") => current = Some(("", String::new())),
            _ => after_shell = false,
        }
    }
    blocks
}

/// What a block printed says about itself: no value of the JSON it printed is `null` alone
/// or an object of nulls only (a jq filter that names fields at the wrong level), and no line
/// of other output is `null`.
fn check_printed(name: &str, code: &str, printed: &str) {
    let values: Result<Vec<Value>, _> = serde_json::Deserializer::from_str(printed)
        .into_iter::<Value>()
        .collect();
    let all_null = |v: &Value| match v {
        Value::Null => true,
        Value::Object(o) => !o.is_empty() && o.values().all(Value::is_null),
        _ => false,
    };
    match values {
        Ok(values) => assert!(
            !values.iter().any(all_null),
            "{name}: a block printed nothing but null:\n{code}\n--- printed\n{printed}"
        ),
        Err(_) => assert!(
            !printed.lines().any(|l| l.trim() == "null"),
            "{name}: a block printed a line of null:\n{code}\n--- printed\n{printed}"
        ),
    }
}

/// Whether bash, curl and jq are here; with `CI` set they must be.
fn tools_present() -> bool {
    let ok = ["bash", "curl", "jq"].iter().all(|t| {
        Command::new(t)
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success())
    });
    if !ok {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI is set but bash, curl or jq is missing (.ci/run installs them)"
        );
        eprintln!("skipped: bash, curl and jq are needed to run the documentation's shell blocks");
    }
    ok
}

fn server(tag: &str) -> (Server, PathBuf) {
    let data = std::env::temp_dir().join(format!("contact-sim-docs-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&data);
    let srv = Server::start_with(Config {
        data_dir: data.clone(),
        workers: 2,
        ..Config::default()
    });
    (srv, data)
}

/// The line a script prints between two blocks, to tell their outputs apart.
const BLOCK_END: &str = "@@ end of block @@";

/// Runs shell blocks in one bash (`set -euo pipefail`), in a fresh folder where `crates`
/// leads to the repository's (the meshes it ships), with localhost:8080 replaced by the
/// server's address; checks what each printed ([`check_printed`], and the output the guide
/// shows for it, if any). Returns the folder.
fn run_blocks(name: &str, blocks: &[Block], srv: &Server, scratch: &Path) -> PathBuf {
    let dir = scratch.join(name.replace('/', "-"));
    std::fs::create_dir_all(&dir).unwrap();
    let link = dir.join("crates");
    if !link.exists() {
        std::os::unix::fs::symlink(root().join("crates"), &link).unwrap();
    }
    let addr = srv.addr.to_string();
    let script = blocks
        .iter()
        .map(|b| {
            let code = b
                .code
                .replace("localhost:8080", &addr)
                .replace("127.0.0.1:8080", &addr);
            format!("{code}printf '\\n{BLOCK_END}\\n'\n")
        })
        .collect::<Vec<_>>()
        .join("");
    let t0 = std::time::Instant::now();
    let out = Command::new("bash")
        .arg("-c")
        .arg(format!("set -euo pipefail\n{script}"))
        .current_dir(&dir)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "{name}: the shell blocks failed ({}):\n{script}\n--- stdout\n{stdout}\n--- stderr\n{stderr}",
        out.status
    );
    // A refused request is answered with problem+json; a script of curl lines would go on.
    assert!(
        !stdout.contains("\"status\":5") && !stdout.contains("\"title\":\"internal"),
        "{name}: a server error:\n{stdout}"
    );
    let printed: Vec<&str> = stdout.split(&format!("\n{BLOCK_END}\n")).collect();
    assert_eq!(printed.len(), blocks.len() + 1, "{name}: {stdout}");
    for (b, printed) in blocks.iter().zip(&printed) {
        check_printed(name, &b.code, printed);
        if let Some(expected) = &b.expected {
            assert_eq!(
                printed.trim(),
                expected.trim(),
                "{name}: the block prints other than the guide shows:\n{}",
                b.code
            );
        }
    }
    eprintln!(
        "{name}: {} blocks ran in {:.1} s",
        blocks.len(),
        t0.elapsed().as_secs_f64()
    );
    dir
}

#[test]
fn quick_start_runs_as_written() {
    if !tools_present() {
        return;
    }
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let blocks = blocks(&readme, Some("### By curl"));
    assert!(
        blocks.len() >= 2,
        "README's quick start has its curl blocks"
    );
    let (srv, data) = server("quickstart");
    let scratch = data.join("scratch");
    let dir = run_blocks("README", &blocks, &srv, &scratch);
    // What the quick start says it saves is there: a VTU and the archive of the same job.
    let files: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    let vtu = files
        .iter()
        .find(|f| f.ends_with(".vtu"))
        .expect("a VTU file");
    let vtu_text = std::fs::read_to_string(dir.join(vtu)).unwrap();
    assert!(vtu_text.contains("<VTKFile") && vtu_text.contains("zeta"));
    assert!(files.iter().any(|f| f.ends_with(".tar")));
    srv.stop();
    let _ = std::fs::remove_dir_all(&data);
}

#[test]
fn tutorials_and_how_tos_run_as_written() {
    if !tools_present() {
        return;
    }
    let (srv, data) = server("guide");
    let scratch = data.join("scratch");
    for chapter in [
        "tutorial/first-2d-job.md",
        "tutorial/first-3d-body.md",
        "tutorial/first-study.md",
        "how-to/own-mesh.md",
        "how-to/paraview.md",
        "reference/http-api.md",
    ] {
        let text = std::fs::read_to_string(root().join("docs/src").join(chapter)).unwrap();
        // Blocks that talk to the service; building, installing and other machines' set-up
        // are not run here.
        let blocks: Vec<Block> = blocks(&text, None)
            .into_iter()
            .filter(|b| {
                let b = &b.code;
                b.contains("localhost:8080") && !b.contains("cargo ") && !b.contains("pip ")
            })
            .collect();
        assert!(!blocks.is_empty(), "{chapter} has shell blocks to run");
        run_blocks(chapter, &blocks, &srv, &scratch);
    }
    srv.stop();
    let _ = std::fs::remove_dir_all(&data);
}
