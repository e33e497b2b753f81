//! The browser client (GET /, api/client/): how its files are served, and the client itself
//! in a real browser. The second test starts the real server on an ephemeral port and runs
//! `node tests/browser/client.mjs <base-url> <screenshot-dir>` (playwright-core driving
//! Debian's headless Chromium; see that script for what it checks). It needs
//! /usr/bin/chromium (or $CHROMIUM), node and `npm ci` in tests/browser; without them it is
//! skipped with a message, except when $CI is set, where it fails (.ci/run installs them).
//! Screenshots and the script's log go to target/browser-artifacts/.

mod common;

use common::server::{get, Server};
use contact_sim::Config;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn target_dir() -> PathBuf {
    match std::env::var_os("CARGO_TARGET_DIR").map(PathBuf::from) {
        Some(d) if d.is_absolute() => d,
        Some(d) => root().join(d),
        None => root().join("target"),
    }
}

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("contact-sim-browser-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn start(tag: &str) -> (Server, PathBuf) {
    let dir = temp_dir(tag);
    let srv = Server::start_with(Config {
        data_dir: dir.clone(),
        workers: 2,
        ..Config::default()
    });
    (srv, dir)
}

/// The user guide built by mdBook, served from `--guide-dir` at /guide/: its pages by their
/// relative paths, a folder as its index, nothing outside the folder; without the flag, a
/// 404 saying how to build and serve it.
#[test]
fn the_user_guide_is_served_from_its_folder() {
    let book = temp_dir("book");
    std::fs::create_dir_all(book.join("tutorial")).unwrap();
    std::fs::create_dir_all(book.join("css")).unwrap();
    std::fs::write(book.join("index.html"), "<h1>guide</h1>").unwrap();
    std::fs::write(book.join("tutorial/first.html"), "<h1>first</h1>").unwrap();
    std::fs::write(book.join("tutorial/index.html"), "<h1>tutorials</h1>").unwrap();
    std::fs::write(book.join("css/general.css"), "body {}").unwrap();
    let secret = temp_dir("outside");
    std::fs::create_dir_all(&secret).unwrap();
    std::fs::write(secret.join("secret.txt"), "no").unwrap();
    let dir = temp_dir("guide");
    let srv = Server::start_with(Config {
        data_dir: dir.clone(),
        workers: 0,
        guide_dir: Some(book.clone()),
        ..Config::default()
    });
    let a = srv.addr;
    let root = get(a, "/guide", &[]);
    assert_eq!(
        (root.status, root.header("location")),
        (308, Some("/guide/"))
    );
    let index = get(a, "/guide/", &[]);
    assert_eq!(index.status, 200);
    assert_eq!(
        index.header("content-type"),
        Some("text/html; charset=utf-8")
    );
    assert_eq!(index.body, b"<h1>guide</h1>");
    assert_eq!(
        get(a, "/guide/tutorial/first.html", &[]).body,
        b"<h1>first</h1>"
    );
    assert_eq!(get(a, "/guide/tutorial/", &[]).body, b"<h1>tutorials</h1>");
    let css = get(a, "/guide/css/general.css", &[]);
    assert_eq!(css.header("content-type"), Some("text/css; charset=utf-8"));
    let name = secret.file_name().unwrap().to_str().unwrap();
    for bad in [
        "/guide/nope.html".to_string(),
        format!("/guide/../{name}/secret.txt"),
        format!("/guide/%2E%2E/{name}/secret.txt"),
        "/guide//etc/passwd".to_string(),
    ] {
        let r = get(a, &bad, &[]);
        assert_eq!(r.status, 404, "{bad}: {}", String::from_utf8_lossy(&r.body));
    }
    srv.stop();
    let (none, none_dir) = start("no-guide");
    let r = get(none.addr, "/guide/", &[]);
    assert_eq!(r.status, 404);
    assert!(String::from_utf8_lossy(&r.body).contains("--guide-dir"));
    none.stop();
    for d in [book, secret, dir, none_dir] {
        let _ = std::fs::remove_dir_all(d);
    }
}

#[test]
fn client_files_are_served_with_types_and_etags() {
    let (srv, dir) = start("files");
    let a = srv.addr;

    let page = get(a, "/", &[]);
    assert_eq!(page.status, 200);
    assert_eq!(
        page.header("content-type"),
        Some("text/html; charset=utf-8")
    );
    let html = String::from_utf8_lossy(&page.body).to_string();
    assert!(html.contains(r#"<script type="module" src="/client/app.js">"#));
    assert_eq!(page.header("cache-control"), Some("no-cache"));
    let etag = page.header("etag").expect("ETag").to_string();
    assert!(etag.starts_with('"') && etag.ends_with('"'), "{etag}");

    // Revalidation: the same ETag gives 304 without a body; another gives the file.
    let again = get(a, "/", &[("If-None-Match", &etag)]);
    assert_eq!(again.status, 304);
    assert!(again.body.is_empty());
    assert_eq!(again.header("etag"), Some(etag.as_str()));
    assert_eq!(get(a, "/", &[("If-None-Match", "\"other\"")]).status, 200);

    for (file, ct) in [
        ("app.js", "text/javascript; charset=utf-8"),
        ("viewer.js", "text/javascript; charset=utf-8"),
        ("style.css", "text/css; charset=utf-8"),
        ("index.html", "text/html; charset=utf-8"),
        ("viewer3d.js", "text/javascript; charset=utf-8"),
        // The vendored three.js (the page's import map names these paths).
        (
            "vendor/three/build/three.module.js",
            "text/javascript; charset=utf-8",
        ),
        (
            "vendor/three/build/three.core.js",
            "text/javascript; charset=utf-8",
        ),
        (
            "vendor/three/examples/jsm/controls/OrbitControls.js",
            "text/javascript; charset=utf-8",
        ),
        ("vendor/three/LICENSE", "text/plain; charset=utf-8"),
    ] {
        let r = get(a, &format!("/client/{file}"), &[]);
        assert_eq!(r.status, 200, "{file}");
        assert_eq!(r.header("content-type"), Some(ct), "{file}");
        assert_eq!(r.header("x-content-type-options"), Some("nosniff"));
        let on_disk = std::fs::read(root().join("api/client").join(file)).unwrap();
        assert_eq!(r.body, on_disk, "{file} is served as it is in api/client/");
    }
    // Every module the page imports is served, vendored ones in subdirectories too (a
    // missing entry in client.rs would be a 404 only a browser would notice).
    let mut files = Vec::new();
    client_files(&root().join("api/client"), "", &mut files);
    assert!(files.len() > 10, "{files:?}");
    for name in &files {
        assert_eq!(
            get(a, &format!("/client/{name}"), &[]).status,
            200,
            "{name}"
        );
    }
    // The import map of the page points at served files.
    for path in [
        "/client/vendor/three/build/three.module.js",
        "/client/vendor/three/examples/jsm/",
    ] {
        assert!(html.contains(path), "index.html's import map names {path}");
    }

    for bad in [
        "/client/nope.js",
        "/client/..%2Fapp.rs",
        "/client/",
        "/client/vendor",
        "/client/vendor/three",
        "/client/vendor/three/../../app.js",
        "/client/vendor/three/build/../LICENSE",
        "/client/vendor%2Fthree%2FLICENSE/x",
    ] {
        let r = get(a, bad, &[]);
        assert_eq!(r.status, 404, "{bad}");
        assert_eq!(
            r.header("content-type"),
            Some("application/problem+json"),
            "{bad}"
        );
    }
    // The icon the pages name and browsers ask for by themselves; /docs/ as people type it.
    let icon = get(a, "/favicon.ico", &[]);
    assert_eq!(icon.status, 200);
    assert_eq!(icon.header("content-type"), Some("image/svg+xml"));
    assert_eq!(icon.body, get(a, "/client/favicon.svg", &[]).body);
    assert!(html.contains(r#"<link rel="icon" href="/client/favicon.svg""#));
    let slash = get(a, "/docs/", &[]);
    assert_eq!(slash.status, 308);
    assert_eq!(slash.header("location"), Some("/docs"));
    srv.stop();
    let _ = std::fs::remove_dir_all(dir);
}

/// The files under `dir` (recursively), as `prefix`-relative paths with `/` separators.
fn client_files(dir: &std::path::Path, prefix: &str, out: &mut Vec<String>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let entry = entry.unwrap();
        let name = format!("{prefix}{}", entry.file_name().to_string_lossy());
        if entry.file_type().unwrap().is_dir() {
            client_files(&entry.path(), &format!("{name}/"), out);
        } else {
            out.push(name);
        }
    }
}

/// Why the browser test cannot run here, if it cannot.
fn missing_prerequisites(chromium: &str) -> Option<String> {
    if !std::path::Path::new(chromium).exists() {
        return Some(format!(
            "no Chromium at {chromium} (apt-get install chromium, or set CHROMIUM)"
        ));
    }
    let node = Command::new("node")
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status();
    if !node.is_ok_and(|s| s.success()) {
        return Some("node is not on the PATH".into());
    }
    if !root()
        .join("tests/browser/node_modules/playwright-core/package.json")
        .exists()
    {
        return Some(
            "tests/browser/node_modules is missing (run `npm ci` in tests/browser)".into(),
        );
    }
    None
}

#[test]
fn client_in_chromium() {
    let chromium = std::env::var("CHROMIUM").unwrap_or_else(|_| "/usr/bin/chromium".into());
    if let Some(why) = missing_prerequisites(&chromium) {
        if std::env::var_os("CI").is_some() {
            panic!("the browser test cannot run although CI is set: {why}");
        }
        eprintln!("skipping the browser test: {why}");
        return;
    }
    let (srv, dir) = start("chromium");
    let out = target_dir().join("browser-artifacts");
    std::fs::create_dir_all(&out).unwrap();
    let log_path = out.join("client.log");
    let log = std::fs::File::create(&log_path).unwrap();
    let mut child = Command::new("node")
        .arg(root().join("tests/browser/client.mjs"))
        .arg(srv.url())
        .arg(&out)
        .env("CHROMIUM", &chromium)
        .stdin(Stdio::null())
        .stdout(log.try_clone().unwrap())
        .stderr(log)
        .spawn()
        .expect("run node");
    // The script has its own time limit; this one only guards against a stuck node.
    let deadline = Instant::now() + Duration::from_secs(300);
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break Some(s);
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(200));
    };
    let output = std::fs::read_to_string(&log_path).unwrap_or_default();
    print!("{output}");
    srv.stop();
    let _ = std::fs::remove_dir_all(dir);
    match status {
        Some(s) => assert!(
            s.success(),
            "browser tests failed ({s}); output above, screenshots in {}",
            out.display()
        ),
        None => panic!("browser tests did not finish in 300 s; output above"),
    }
}
