//! API keys, owners and quotas against the real binary (`serve --auth required`), keys made
//! with `contact-sim keys`:
//!
//! * `routes_by_caller_on_sqlite` / `routes_by_caller_on_postgres`: every route × {no key,
//!   owner, other owner, admin, revoked key} with its exact status, on the embedded store and
//!   on PostgreSQL with an API-only node and a worker node; another owner's 404 is the very
//!   answer of a job or mesh that does not exist, a revoked key's 401 that of an unknown one;
//!   idempotency keys and the identical-scene shortcut are per owner; a revocation is
//!   refused at the next request; audit lines name who did what from where; no token appears
//!   in any answer, log line, data file or database file.
//! * `quotas_and_fair_claims`: per-key quotas (active jobs, stored bytes, compute per day)
//!   answer their problem types; with one worker, an owner who floods 200 jobs does not
//!   delay another owner's single job by more than the one job running.
//! * `serve_refuses_to_start_exposed_without_a_decision`: a non-loopback address needs
//!   `--auth`.
//! * `a_first_start_without_a_key_waits_for_one`: `--auth required` on an empty store (a
//!   fresh container) starts, answers 503 on `/healthz` and 401 elsewhere, and serves once
//!   `contact-sim keys add` has run beside it.

mod service_support;

use serde_json::{json, Value};
use service_support::postgres::Postgres;
use service_support::*;
use std::net::SocketAddr;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

fn binary() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_contact-sim"));
    c.env("RUST_LOG", "info");
    c
}

/// `contact-sim keys ARGS… STORE…`; panics unless it succeeds. Returns (stdout, stderr).
fn keys(store: &[&str], args: &[&str]) -> (String, String) {
    let out = binary()
        .arg("keys")
        .args(args)
        .args(store)
        .output()
        .unwrap();
    let (o, e) = (
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    );
    assert!(out.status.success(), "keys {args:?}: {e}");
    (o, e)
}

/// A new key's token (what `keys add` prints on stdout, alone).
fn add_key(store: &[&str], args: &[&str]) -> String {
    let mut all = vec!["add"];
    all.extend_from_slice(args);
    let (out, err) = keys(store, &all);
    assert!(err.contains("contact_sim::audit"), "no audit line: {err}");
    let token = out.trim().to_string();
    assert!(token.starts_with("csk_") && token.len() == 47, "{out:?}");
    token
}

/// The callers of the table, in its column order.
const CALLERS: [&str; 5] = ["no key", "owner", "other", "admin", "revoked"];

struct Tokens {
    owner: String,
    other: String,
    admin: String,
    revoked: String,
}

impl Tokens {
    /// Makes alice, bob, root (admin) and carol (used once, then revoked by the caller).
    fn make(store: &[&str]) -> Tokens {
        Tokens {
            owner: add_key(store, &["alice"]),
            other: add_key(store, &["bob"]),
            admin: add_key(store, &["root", "--admin"]),
            revoked: add_key(store, &["carol"]),
        }
    }

    fn of(&self, who: usize) -> Option<&str> {
        match who {
            1 => Some(&self.owner),
            2 => Some(&self.other),
            3 => Some(&self.admin),
            4 => Some(&self.revoked),
            _ => None,
        }
    }

    fn all(&self) -> [&str; 4] {
        [&self.owner, &self.other, &self.admin, &self.revoked]
    }
}

/// One request with `token` as its bearer key.
fn call(
    addr: SocketAddr,
    method: &str,
    path: &str,
    token: Option<&str>,
    headers: &[(&str, &str)],
    body: &[u8],
) -> Resp {
    let auth = token.map(|t| format!("Bearer {t}"));
    let mut h: Vec<(&str, &str)> = headers.to_vec();
    if let Some(a) = &auth {
        h.push(("Authorization", a));
    }
    try_http(addr, method, path, &h, body, Duration::from_secs(60))
        .unwrap_or_else(|e| panic!("{method} {path}: {e}"))
}

const JSON: (&str, &str) = ("Content-Type", "application/json");
const OCTET: (&str, &str) = ("Content-Type", "application/octet-stream");

fn submit(addr: SocketAddr, token: &str, scene: &Value) -> Resp {
    call(
        addr,
        "POST",
        "/jobs",
        Some(token),
        &[JSON],
        scene.to_string().as_bytes(),
    )
}

fn wait_done(addr: SocketAddr, token: &str, id: &str) -> Value {
    let t = Instant::now();
    loop {
        let j = call(addr, "GET", &format!("/jobs/{id}"), Some(token), &[], b"").json();
        if ["succeeded", "failed", "cancelled"].contains(&j["status"].as_str().unwrap_or("")) {
            return j;
        }
        assert!(
            t.elapsed() < Duration::from_secs(120),
            "job {id} stuck: {j}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// A test mesh of the core: the presets' meshes, else the reader's test files.
fn test_mesh(name: &str) -> Vec<u8> {
    let core = Path::new(env!("CARGO_MANIFEST_DIR")).join("crates/contact-core");
    let p = core.join("preset-meshes").join(name);
    let p = if p.exists() {
        p
    } else {
        core.join("tests/meshes").join(name)
    };
    std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

fn ids(list: &Value, member: &str) -> Vec<String> {
    list[member]
        .as_array()
        .unwrap()
        .iter()
        .map(|j| j["id"].as_str().unwrap().to_string())
        .collect()
}

/// Everything a caller was answered, for the token check.
struct Answers(Vec<String>);

/// Runs the route table against a service with authentication required; `revoke` revokes
/// carol's key through the store (as an administrator would, on any node).
fn route_table(addr: SocketAddr, t: &Tokens, revoke: &dyn Fn()) -> Answers {
    let mut seen = Answers(Vec::new());
    // Carol's key works until it is revoked; then it is refused at once.
    assert_eq!(
        call(addr, "GET", "/jobs", Some(&t.revoked), &[], b"").status,
        200
    );
    revoke();

    // Alice's resources: a succeeded job J, two more to delete, a mesh M and one more.
    let scene = small_scene("auth-j");
    let r = submit(addr, &t.owner, &scene);
    assert_eq!(r.status, 202, "{}", r.text());
    let j = r.json()["id"].as_str().unwrap().to_string();
    let j2 = submit(addr, &t.owner, &small_scene("auth-j2")).json()["id"]
        .as_str()
        .unwrap()
        .to_string();
    let j3 = submit(addr, &t.owner, &small_scene("auth-j3")).json()["id"]
        .as_str()
        .unwrap()
        .to_string();
    for id in [&j, &j2, &j3] {
        assert_eq!(wait_done(addr, &t.owner, id)["status"], "succeeded");
    }
    let plate = test_mesh("plate-with-hole.msh");
    let r = call(addr, "POST", "/meshes", Some(&t.owner), &[OCTET], &plate);
    assert_eq!(r.status, 201, "{}", r.text());
    let m = r.json()["id"].as_str().unwrap().to_string();
    let plate2 = test_mesh("plate-with-hole-binary.msh");
    let r = call(addr, "POST", "/meshes", Some(&t.owner), &[OCTET], &plate2);
    assert_eq!(r.status, 201, "{}", r.text());
    let m2 = r.json()["id"].as_str().unwrap().to_string();

    let absent_job = uuid::Uuid::new_v4().to_string();
    let absent_mesh = "0".repeat(64);
    let read = [401, 200, 404, 200, 401];
    let rows: Vec<(&str, String, [u16; 5])> = vec![
        ("GET", "/jobs".into(), [401, 200, 200, 200, 401]),
        ("GET", format!("/jobs/{j}"), read),
        // The id percent-encoded, as the router's extractor decodes it.
        ("GET", format!("/jobs/{}", j.replace('-', "%2D")), read),
        (
            "GET",
            format!("/jobs/{}/summary", j.replace('-', "%2d")),
            read,
        ),
        ("GET", format!("/jobs/{j}/events"), read),
        ("GET", format!("/jobs/{j}/summary"), read),
        ("GET", format!("/jobs/{j}/mesh"), read),
        ("GET", format!("/jobs/{j}/fields?step=last"), read),
        ("GET", format!("/jobs/{j}/fields/last.vtu"), read),
        ("GET", format!("/jobs/{j}/result.pvd"), read),
        ("GET", format!("/jobs/{j}/archive.tar"), read),
        // A simulation has no report: 404 for its owner too.
        (
            "GET",
            format!("/jobs/{j}/report.svg"),
            [401, 404, 404, 404, 401],
        ),
        // Finished: 409 for whoever may see it.
        (
            "POST",
            format!("/jobs/{j}/cancel"),
            [401, 409, 404, 409, 401],
        ),
        ("GET", "/meshes".into(), [401, 200, 200, 200, 401]),
        ("GET", format!("/meshes/{m}"), read),
        ("GET", format!("/meshes/{m}/file"), read),
        ("GET", "/metrics".into(), [401, 403, 403, 200, 401]),
        ("GET", "/healthz".into(), [200; 5]),
        ("GET", "/openapi.yaml".into(), [200; 5]),
        ("GET", "/scene.schema.json".into(), [200; 5]),
        ("GET", "/presets".into(), [200; 5]),
        ("GET", "/".into(), [200; 5]),
    ];
    for (method, path, want) in &rows {
        for (who, want) in want.iter().enumerate() {
            let r = call(addr, method, path, t.of(who), &[], b"");
            assert_eq!(
                r.status,
                *want,
                "{method} {path} as {}: {}",
                CALLERS[who],
                r.text()
            );
            seen.0.push(format!("{:?} {}", r.headers, r.text()));
            if r.status == 401 {
                assert_eq!(
                    r.header("www-authenticate"),
                    Some("Bearer realm=\"contact-sim\"")
                );
                assert_eq!(r.header("content-type"), Some("application/problem+json"));
            }
            // Another owner's job or mesh answers exactly as one that does not exist.
            if who == 2 && *want == 404 && (path.contains(&j) || path.contains(&m)) {
                let ghost = path.replace(&j, &absent_job).replace(&m, &absent_mesh);
                let g = call(addr, method, &ghost, t.of(who), &[], b"");
                assert_eq!(g.status, 404);
                assert_eq!(
                    g.text().replace(&absent_job, &j).replace(&absent_mesh, &m),
                    r.text(),
                    "{method} {path}: another owner's answer differs from a missing one's"
                );
            }
        }
    }

    // Unknown, revoked and malformed keys are answered alike.
    let unknown = format!("csk_{}", "A".repeat(43));
    let a = call(addr, "GET", "/jobs", Some(&unknown), &[], b"");
    let b = call(addr, "GET", "/jobs", Some(&t.revoked), &[], b"");
    let c = call(addr, "GET", "/jobs", Some("not-a-key"), &[], b"");
    let d = call(addr, "GET", "/jobs", None, &[], b"");
    for x in [&b, &c, &d] {
        assert_eq!((x.status, x.text()), (a.status, a.text()));
        assert_eq!(x.header("www-authenticate"), a.header("www-authenticate"));
    }
    assert_eq!(a.json()["type"], "/problems/unauthorized");

    // Listings are per owner; an admin sees all and lists by owner.
    let alice_jobs = ids(
        &call(addr, "GET", "/jobs", Some(&t.owner), &[], b"").json(),
        "jobs",
    );
    assert!(
        alice_jobs.contains(&j) && alice_jobs.len() == 3,
        "{alice_jobs:?}"
    );
    let bob_jobs = ids(
        &call(addr, "GET", "/jobs", Some(&t.other), &[], b"").json(),
        "jobs",
    );
    assert!(bob_jobs.is_empty(), "{bob_jobs:?}");
    let by_owner = call(
        addr,
        "GET",
        "/jobs?owner=alice&limit=2",
        Some(&t.admin),
        &[],
        b"",
    );
    assert_eq!(ids(&by_owner.json(), "jobs").len(), 2);
    assert!(by_owner.json()["next"]
        .as_str()
        .unwrap()
        .contains("owner=alice"));
    let r = call(addr, "GET", "/jobs?owner=alice", Some(&t.other), &[], b"");
    assert_eq!(r.status, 403);
    assert_eq!(
        ids(
            &call(addr, "GET", "/meshes", Some(&t.owner), &[], b"").json(),
            "meshes"
        )
        .len(),
        2
    );
    assert!(ids(
        &call(addr, "GET", "/meshes", Some(&t.other), &[], b"").json(),
        "meshes"
    )
    .is_empty());
    assert_eq!(
        ids(
            &call(addr, "GET", "/meshes?owner=alice", Some(&t.admin), &[], b"").json(),
            "meshes"
        )
        .len(),
        2
    );
    // Health details and the warning-free admin view.
    let h = call(addr, "GET", "/healthz", None, &[], b"").json();
    assert_eq!(h, json!({"status": "ok"}));
    let h = call(addr, "GET", "/healthz", Some(&t.admin), &[], b"").json();
    assert!(
        h.get("workers").is_some() && h.get("warning").is_none(),
        "{h}"
    );

    // The identical-scene shortcut answers the owner with its job, never another owner.
    let r = submit(addr, &t.owner, &scene);
    assert_eq!(
        (r.status, r.json()["id"].as_str().unwrap()),
        (200, j.as_str())
    );
    let r = submit(addr, &t.other, &scene);
    assert_eq!(r.status, 202);
    let bobs = r.json()["id"].as_str().unwrap().to_string();
    assert_ne!(bobs, j);
    // Idempotency keys are per owner: the same key, two owners, two jobs.
    let idem = |token: &str| {
        let r = call(
            addr,
            "POST",
            "/jobs",
            Some(token),
            &[JSON, ("Idempotency-Key", "shared-key")],
            small_scene("auth-idem").to_string().as_bytes(),
        );
        assert_eq!(r.status, 202, "{}", r.text());
        r.json()["id"].as_str().unwrap().to_string()
    };
    let (ia, ib) = (idem(&t.owner), idem(&t.other));
    assert_ne!(ia, ib);
    assert_eq!(idem(&t.owner), ia);
    // A scene on another owner's mesh is refused as on a mesh that does not exist.
    let mut on_mesh = contact_core::scene::presets::get("plate-with-hole").unwrap();
    on_mesh["domain"] = json!({"mesh": m});
    let r = submit(addr, &t.other, &on_mesh);
    assert_eq!(r.status, 422, "{}", r.text());
    on_mesh["domain"] = json!({"mesh": absent_mesh});
    let ghost = submit(addr, &t.other, &on_mesh);
    assert_eq!(ghost.text().replace(&absent_mesh, &m), r.text());
    for id in [&bobs, &ia, &ib] {
        wait_done(addr, &t.admin, id);
    }

    // Deletions: refused to others, done by the owner and by an admin.
    for (who, want) in [(0, 401), (2, 404), (4, 401), (1, 204)] {
        let r = call(addr, "DELETE", &format!("/jobs/{j2}"), t.of(who), &[], b"");
        assert_eq!(
            r.status,
            want,
            "DELETE job as {}: {}",
            CALLERS[who],
            r.text()
        );
        seen.0.push(r.text());
    }
    assert_eq!(
        call(
            addr,
            "DELETE",
            &format!("/jobs/{j3}"),
            Some(&t.admin),
            &[],
            b""
        )
        .status,
        204
    );
    assert_eq!(
        call(
            addr,
            "GET",
            &format!("/jobs/{j3}"),
            Some(&t.owner),
            &[],
            b""
        )
        .status,
        404
    );
    // Uploads: the same bytes are a mesh of bob's own (201: new to him), with his time.
    for (who, want) in [(0, 401), (4, 401), (2, 201), (2, 200)] {
        let r = call(addr, "POST", "/meshes", t.of(who), &[OCTET], &plate);
        assert_eq!(
            r.status,
            want,
            "POST /meshes as {}: {}",
            CALLERS[who],
            r.text()
        );
        seen.0.push(r.text());
    }
    let alice_m = call(
        addr,
        "GET",
        &format!("/meshes/{m}"),
        Some(&t.owner),
        &[],
        b"",
    )
    .json();
    let bob_m = call(
        addr,
        "GET",
        &format!("/meshes/{m}"),
        Some(&t.other),
        &[],
        b"",
    )
    .json();
    assert!(bob_m["created_at"].as_str() > alice_m["created_at"].as_str());
    for (who, want) in [(0, 401), (4, 401), (1, 204), (1, 404)] {
        let r = call(addr, "DELETE", &format!("/meshes/{m}"), t.of(who), &[], b"");
        assert_eq!(
            r.status,
            want,
            "DELETE mesh as {}: {}",
            CALLERS[who],
            r.text()
        );
    }
    // Bob's record and the file stay his.
    let r = call(
        addr,
        "GET",
        &format!("/meshes/{m}/file"),
        Some(&t.other),
        &[],
        b"",
    );
    assert_eq!((r.status, r.body.len()), (200, plate.len()));
    // Another owner cannot delete alice's second mesh; an admin can.
    assert_eq!(
        call(
            addr,
            "DELETE",
            &format!("/meshes/{m2}"),
            Some(&t.other),
            &[],
            b""
        )
        .status,
        404
    );
    assert_eq!(
        call(
            addr,
            "DELETE",
            &format!("/meshes/{m2}"),
            Some(&t.admin),
            &[],
            b""
        )
        .status,
        204
    );
    assert_eq!(
        call(
            addr,
            "GET",
            &format!("/meshes/{m2}"),
            Some(&t.owner),
            &[],
            b""
        )
        .status,
        404
    );
    seen
}

/// Every file under `dir` (recursively), as bytes.
fn files(dir: &Path, out: &mut Vec<(std::path::PathBuf, Vec<u8>)>) {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return;
    };
    for e in rd.flatten() {
        let p = e.path();
        if p.is_dir() {
            files(&p, out);
        } else if let Ok(b) = std::fs::read(&p) {
            out.push((p, b));
        }
    }
}

/// No token in the answers, the logs, or any file of `dirs`.
fn assert_no_tokens(t: &Tokens, answers: &Answers, logs: &[String], dirs: &[&Path]) {
    let mut all = Vec::new();
    for d in dirs {
        files(d, &mut all);
    }
    assert!(!all.is_empty());
    for token in t.all() {
        // The random part alone, should anything strip the prefix.
        let secret = &token[4..];
        for a in &answers.0 {
            assert!(!a.contains(secret), "a token in an answer: {a}");
        }
        for log in logs {
            assert!(!log.contains(secret), "a token in a log");
        }
        for (path, bytes) in &all {
            let found = bytes.windows(secret.len()).any(|w| w == secret.as_bytes());
            assert!(!found, "a token in {}", path.display());
        }
    }
}

fn api_log(p: &Proc) -> String {
    p.log.lock().unwrap().clone()
}

/// The audit lines of the API node: who, what, from where.
fn assert_audited(api: &Proc) {
    let log = api.log.lock().unwrap().clone();
    let lines: Vec<&str> = log
        .lines()
        .filter(|l| l.contains("contact_sim::audit"))
        .collect();
    let has = |who: &str, action: &str| {
        lines.iter().any(|l| {
            l.contains(&format!("who=\"{who}\""))
                && l.contains(action)
                && l.contains("from=\"127.0.0.1:")
        })
    };
    assert!(has("alice", "action=POST /jobs "), "{lines:#?}");
    assert!(has("alice", "action=DELETE /jobs/"), "{lines:#?}");
    assert!(has("root", "action=DELETE /meshes/"), "{lines:#?}");
    assert!(has("bob", "action=POST /meshes"), "{lines:#?}");
    assert!(
        lines.iter().any(|l| l.contains("resource=\"/jobs/")),
        "{lines:#?}"
    );
    // Failed authentication: the reason and the peer address (never the token: the
    // callers check the whole log for tokens).
    let failed = |reason: &str| {
        lines.iter().any(|l| {
            l.contains("who=\"unauthenticated\"")
                && l.contains(&format!("reason=\"{reason}\""))
                && l.contains("outcome=\"401\"")
                && l.contains("from=\"127.0.0.1:")
        })
    };
    assert!(failed("no key"), "{lines:#?}");
    assert!(failed("unknown or revoked key"), "{lines:#?}");
}

#[test]
fn routes_by_caller_on_sqlite() {
    let dir = TempDir::new("auth-sqlite");
    let d = dir.0.to_str().unwrap();
    let store = ["--data-dir", d];
    let t = Tokens::make(&store);
    let api = Proc::start(
        &dir.0,
        &["--auth", "required", "--workers", "1", "--submit-rate", "0"],
    );
    let revoke = || {
        keys(&store, &["revoke", "carol"]);
    };
    let answers = route_table(api.addr, &t, &revoke);
    let (list, _) = keys(&store, &["list"]);
    let list: Value = serde_json::from_str(&list).unwrap();
    let carol = &list["keys"]
        .as_array()
        .unwrap()
        .iter()
        .find(|k| k["name"] == "carol")
        .unwrap();
    assert!(carol["revoked_at"].is_string() && carol["last_used_at"].is_string());
    assert_audited(&api);
    let log = api_log(&api);
    api.terminate();
    assert_no_tokens(&t, &answers, &[log], &[&dir.0]);
}

#[test]
fn routes_by_caller_on_postgres() {
    let Some(pg) = Postgres::start("auth") else {
        return;
    };
    let url = pg.create_database("auth");
    let dir = TempDir::new("auth-pg");
    let store = ["--store", url.as_str()];
    // The keys exist before the API node starts (it refuses to start without one).
    let t = Tokens::make(&store);
    let api = api_node(&dir.0, &url);
    let worker = Proc::worker(&dir.0, &["--store", &url, "--node", "w1", "--workers", "1"]);
    let revoke = || {
        keys(&store, &["revoke", "carol"]);
    };
    let answers = route_table(api.addr, &t, &revoke);
    assert_audited(&api);
    let logs = [api_log(&api), api_log(&worker)];
    api.terminate();
    worker.terminate();
    assert_no_tokens(&t, &answers, &logs, &[&dir.0, pg.root()]);
}

/// RFC 3339 seconds of a job resource's time.
fn secs(t: &Value) -> f64 {
    let s = t.as_str().unwrap_or_else(|| panic!("no time: {t}"));
    s.parse::<jiff::Timestamp>().unwrap().as_millisecond() as f64 / 1000.0
}

#[test]
fn quotas_and_fair_claims() {
    let dir = TempDir::new("auth-quota");
    let d = dir.0.to_str().unwrap();
    let store = ["--data-dir", d];
    let alice = add_key(&store, &["alice"]);
    let bob = add_key(&store, &["bob", "--max-active-jobs", "1"]);
    let carol = add_key(&store, &["carol", "--max-stored-bytes", "1000"]);
    let dave = add_key(&store, &["dave", "--max-compute-seconds", "0.000001"]);
    let erin = add_key(&store, &["erin", "--max-active-jobs", "1"]);
    let root = add_key(&store, &["root", "--admin"]);
    let api = Proc::start(
        &dir.0,
        &["--auth", "required", "--workers", "1", "--submit-rate", "0"],
    );
    let a = api.addr;
    let quota = |r: &Resp, status: u16, name: &str| {
        assert_eq!(r.status, status, "{}", r.text());
        let p = r.json();
        assert_eq!(p["type"], "/problems/quota-exceeded", "{p}");
        assert_eq!(p["quota"]["name"], name, "{p}");
        p
    };

    // Compute per day: the first job runs (nothing used yet), and its worker-seconds then
    // exceed the day's allowance until midnight UTC.
    let r = submit(a, &dave, &small_scene("dave-1"));
    assert_eq!(r.status, 202);
    wait_done(a, &dave, r.json()["id"].as_str().unwrap());
    let r = submit(a, &dave, &small_scene("dave-2"));
    let p = quota(&r, 429, "compute_s_per_day");
    assert_eq!(p["quota"]["limit"], 0.000001);
    assert!(p["quota"]["used"].as_f64().unwrap() > 0.000001, "{p}");
    let now = jiff::Timestamp::now().as_second();
    let midnight = (now / 86_400 + 1) * 86_400;
    assert_eq!(secs(&p["quota"]["reset"]) as i64, midnight, "{p}");
    let wait: i64 = r.header("retry-after").unwrap().parse().unwrap();
    assert!((wait - (midnight - now)).abs() <= 2, "Retry-After {wait}");
    // Stored bytes: a size, 413, for a job's estimated results and for a mesh.
    quota(
        &submit(a, &carol, &small_scene("carol")),
        413,
        "stored_bytes",
    );
    let plate = test_mesh("plate-with-hole.msh");
    let r = call(a, "POST", "/meshes", Some(&carol), &[OCTET], &plate);
    quota(&r, 413, "stored_bytes");

    fair_claims(a, &alice, &bob, &root, "SQLite");
    let p = quota(&submit(a, &bob, &small_scene("bob-2")), 429, "active_jobs");
    assert_eq!(p["quota"]["limit"], 1.0);
    // At the limit, a retry with its Idempotency-Key still gets its job back (the worker is
    // busy with alice's flood: erin's job stays queued meanwhile).
    let keyed = |name: &str, key: &str| {
        call(
            a,
            "POST",
            "/jobs",
            Some(&erin),
            &[JSON, ("Idempotency-Key", key)],
            small_scene(name).to_string().as_bytes(),
        )
    };
    let first = keyed("erin-1", "e1");
    assert_eq!(first.status, 202, "{}", first.text());
    let again = keyed("erin-1", "e1");
    assert_eq!(
        (again.status, again.json()["id"].clone()),
        (202, first.json()["id"].clone())
    );
    assert_eq!(again.json()["owner"], "erin");
    quota(&keyed("erin-2", "e2"), 429, "active_jobs");
}

/// One worker; alice floods it with 200 jobs, then bob submits one, which must start
/// when the job running at his submission ends (least recently served owner first).
fn fair_claims(a: SocketAddr, alice: &str, bob: &str, root: &str, store: &str) {
    let t = Instant::now();
    let flood: Vec<String> = (0..200)
        .map(|i| {
            let r = submit(a, alice, &long_scene(&format!("flood-{i}"), 32, 300, 1));
            assert_eq!(r.status, 202, "{}", r.text());
            r.json()["id"].as_str().unwrap().to_string()
        })
        .collect();
    let flooded_in = t.elapsed();
    let r = submit(a, bob, &long_scene("bob", 32, 300, 1));
    assert_eq!(r.status, 202);
    let bobs = r.json()["id"].as_str().unwrap().to_string();
    let job = loop {
        let j = call(a, "GET", &format!("/jobs/{bobs}"), Some(bob), &[], b"").json();
        if j["started_at"].is_string() {
            break j;
        }
        assert!(
            t.elapsed() < Duration::from_secs(120),
            "bob's job never started: {j}"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    let (created, started) = (secs(&job["created_at"]), secs(&job["started_at"]));
    let page = call(
        a,
        "GET",
        "/jobs?owner=alice&limit=500",
        Some(root),
        &[],
        b"",
    )
    .json();
    let alices = page["jobs"].as_array().unwrap();
    assert_eq!(alices.len(), flood.len());
    let started_meanwhile = alices
        .iter()
        .filter(|j| j["started_at"].is_string())
        .filter(|j| (created..started).contains(&secs(&j["started_at"])))
        .count();
    let durations: Vec<f64> = alices
        .iter()
        .filter(|j| j["finished_at"].is_string())
        .map(|j| secs(&j["finished_at"]) - secs(&j["started_at"]))
        .collect();
    let longest = durations.iter().cloned().fold(0.0, f64::max);
    let queued = alices.iter().filter(|j| j["status"] == "queued").count();
    eprintln!(
        "fairness ({store}, 1 worker): 200 jobs submitted in {:.2} s; bob's job waited {:.3} s; \
         alice's jobs took up to {longest:.3} s each, {} finished, {queued} still queued",
        flooded_in.as_secs_f64(),
        started - created,
        durations.len()
    );
    // With one worker, nothing of alice's starts between bob's submission and his start:
    // he waits for the job running when he submitted, at most (times are to the ms).
    assert_eq!(started_meanwhile, 0);
    assert!(
        started - created <= longest + 0.01,
        "waited {} s",
        started - created
    );
    assert!(queued > 100, "the flood was not queued: {queued}");
}

#[test]
fn serve_refuses_to_start_exposed_without_a_decision() {
    let dir = TempDir::new("auth-refuse");
    let d = dir.0.to_str().unwrap();
    let serve = |args: &[&str]| {
        binary()
            .args(["serve", "--data-dir", d])
            .args(args)
            .output()
            .unwrap()
    };
    let out = serve(&["--addr", "0.0.0.0:0"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--auth required"));
    // --auth off on every address: served, with the warning at start and on /healthz.
    let (mut child, addr, head) = spawn_serve(d, "0.0.0.0:0", "off");
    assert!(
        head.contains("authentication is off on a non-loopback address"),
        "{head}"
    );
    let h = get(addr, "/healthz").json();
    assert!(
        h["warning"]
            .as_str()
            .unwrap()
            .contains("authentication is off"),
        "{h}"
    );
    // Anonymous use as on a laptop: no key.
    assert_eq!(get(addr, "/jobs").status, 200);
    let _ = child.kill();
    let _ = child.wait();
}

/// `serve --data-dir d --addr addr --auth auth` in the background: the child, the address it
/// listens on (its port read from the log on stderr) and the log up to that line.
fn spawn_serve(d: &str, addr: &str, auth: &str) -> (std::process::Child, SocketAddr, String) {
    let mut child = binary()
        .args(["serve", "--data-dir", d, "--addr", addr, "--auth", auth])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = std::io::BufRead::lines(std::io::BufReader::new(child.stderr.take().unwrap()));
    let mut head = String::new();
    let host = addr.rsplit_once(':').unwrap().0;
    let port = loop {
        let line = lines.next().expect("serve started").unwrap();
        head += &line;
        head.push('\n');
        if let Some(rest) = line.split(&format!("listening on http://{host}:")).nth(1) {
            break rest
                .split_whitespace()
                .next()
                .unwrap()
                .parse::<u16>()
                .unwrap();
        }
    };
    // The rest of the log is not read: drained, so the node never blocks on a full pipe.
    std::thread::spawn(move || lines.for_each(drop));
    (child, ([127, 0, 0, 1], port).into(), head)
}

/// The documented first start of the image (`docker run … contact-sim` with `--auth
/// required` and an empty volume), without Docker: the node starts, says on its log and on
/// `/healthz` (503) that it waits for a key, refuses every non-public request (401), and
/// once `contact-sim keys add` has run on the same data directory beside it, is healthy and
/// serves the key.
#[test]
fn a_first_start_without_a_key_waits_for_one() {
    let dir = TempDir::new("auth-first-start");
    let d = dir.0.to_str().unwrap();
    let (mut child, addr, head) = spawn_serve(d, "127.0.0.1:0", "required");
    assert!(head.contains("no active API key yet"), "{head}");
    let h = get(addr, "/healthz");
    assert_eq!(h.status, 503);
    let detail = h.json()["detail"].as_str().unwrap().to_string();
    assert!(detail.contains("contact-sim keys add"), "{detail}");
    assert_eq!(get(addr, "/jobs").status, 401);
    assert_eq!(
        get(addr, "/presets").status,
        200,
        "public routes are served"
    );

    let out = binary()
        .args(["keys", "add", "admin", "--admin", "--data-dir", d])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let token = String::from_utf8(out.stdout).unwrap().trim().to_string();
    assert_eq!(get(addr, "/healthz").status, 200);
    let jobs = call(addr, "GET", "/jobs", Some(&token), &[], b"");
    assert_eq!(jobs.status, 200, "{}", jobs.text());
    assert_eq!(get(addr, "/jobs").status, 401, "still no anonymous use");
    let _ = child.kill();
    let _ = child.wait();
}

#[test]
fn fair_claims_on_postgres() {
    let Some(pg) = Postgres::start("auth-fair") else {
        return;
    };
    let url = pg.create_database("fair");
    let dir = TempDir::new("auth-fair");
    let store = ["--store", url.as_str()];
    let alice = add_key(&store, &["alice"]);
    let bob = add_key(&store, &["bob"]);
    let root = add_key(&store, &["root", "--admin"]);
    let api = api_node(&dir.0, &url);
    let _worker = Proc::worker(&dir.0, &["--store", &url, "--node", "w1", "--workers", "1"]);
    fair_claims(api.addr, &alice, &bob, &root, "PostgreSQL");
}

/// The p-th percentile of sorted values.
fn percentile(sorted: &[f64], p: f64) -> f64 {
    let i = ((p / 100.0) * (sorted.len().max(1) - 1) as f64).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

/// The hostile-input fuzz (tests/hostile.rs) in short, with authentication on: random and
/// malformed `Authorization` headers on every route are 401 (or a public route's answer),
/// random bodies and mutated scenes with a valid key are 4xx; never a 5xx, never a token
/// in an answer.
#[test]
fn fuzz_with_keys() {
    let dir = TempDir::new("auth-fuzz");
    let d = dir.0.to_str().unwrap();
    let store = ["--data-dir", d];
    let key = add_key(&store, &["fuzzer"]);
    let api = Proc::start(
        &dir.0,
        &[
            "--auth",
            "required",
            "--workers",
            "1",
            "--max-nodes",
            "2000",
            "--submit-rate",
            "0",
        ],
    );
    let a = api.addr;
    let mut rng = Rng::seeded(0xa17_0001);
    let routes = [
        ("GET", "/jobs"),
        ("POST", "/jobs"),
        ("GET", "/meshes"),
        ("POST", "/meshes"),
        ("GET", "/metrics"),
        ("GET", "/jobs/00000000-0000-0000-0000-000000000000/events"),
        ("DELETE", "/jobs/00000000-0000-0000-0000-000000000000"),
        ("GET", "/nope"),
    ];
    let timeout = Duration::from_secs(20);
    let mut statuses = std::collections::BTreeMap::<u16, usize>::new();
    for i in 0..600 {
        let (method, path) = *rng.pick(&routes);
        let header: String = match i % 6 {
            0 => {
                let n = rng.below(200);
                String::from_utf8_lossy(&rng.bytes(n)).into_owned()
            }
            1 => format!("Bearer {}", String::from_utf8_lossy(&rng.bytes(47))),
            2 => format!("Bearer csk_{}", "A".repeat(rng.below(100))),
            3 => format!("Basic {key}"),
            4 => format!("Bearer {}", &key[..rng.below(key.len())]),
            _ => format!("Bearer {key}x"),
        };
        // Header values a client library refuses (control bytes) go on a raw socket.
        let printable: String = header
            .chars()
            .filter(|c| c.is_ascii_graphic() || *c == ' ')
            .collect();
        let r = raw_request(
            a,
            method,
            path,
            &[("Authorization", &printable)],
            b"",
            timeout,
        )
        .unwrap_or_else(|e| panic!("{method} {path} {printable:?}: {e}"));
        *statuses.entry(r.status).or_default() += 1;
        assert_eq!(r.status, 401, "{method} {path} {printable:?}: {}", r.text());
        assert!(!r.text().contains(&key[4..]));
    }
    // With the key: random bodies and mutated scenes are refused with a 4xx.
    let base = small_scene("fuzz").to_string().into_bytes();
    for i in 0..600 {
        let body = if i % 2 == 0 {
            let n = rng.below(400);
            rng.bytes(n)
        } else {
            let mut b = base.clone();
            for _ in 0..1 + rng.below(3) {
                let at = rng.below(b.len());
                b[at] = *rng.pick(b"{}[]\",:0-e");
            }
            b
        };
        let r = call(a, "POST", "/jobs", Some(&key), &[JSON], &body);
        *statuses.entry(r.status).or_default() += 1;
        assert!(r.status < 500, "{}: {}", r.status, r.text());
        assert!(
            r.status >= 400 || r.status == 202 || r.status == 200,
            "{}",
            r.status
        );
    }
    eprintln!("fuzz with keys: 1,200 requests, statuses {statuses:?}");
    assert_eq!(call(a, "GET", "/healthz", None, &[], b"").status, 200);
}

/// The load test (tests/load.rs) in short, with authentication on: 8 clients, each its own
/// key, submit, poll, list and check health for 8 s while the one worker is busy. Every
/// request checks its key in the store: GET latency must stay within the load test's bound.
#[test]
fn load_with_keys() {
    const CLIENTS: usize = 8;
    let dir = TempDir::new("auth-load");
    let d = dir.0.to_str().unwrap();
    let store = ["--data-dir", d];
    let tokens: Vec<String> = (0..CLIENTS)
        .map(|i| add_key(&store, &[&format!("user{i}")]))
        .collect();
    let api = Proc::start(
        &dir.0,
        &[
            "--auth",
            "required",
            "--workers",
            "1",
            "--submit-rate",
            "0",
            "--queue-capacity",
            "100000",
        ],
    );
    let a = api.addr;
    let deadline = Instant::now() + Duration::from_secs(8);
    let handles: Vec<_> = tokens
        .into_iter()
        .enumerate()
        .map(|(n, token)| {
            std::thread::spawn(move || {
                let mut rng = Rng::seeded(0x10ad + n as u64);
                let (mut gets, mut mine, mut k) = (Vec::new(), Vec::<String>::new(), 0);
                while Instant::now() < deadline {
                    let roll = rng.below(100);
                    if roll < 15 || mine.is_empty() {
                        k += 1;
                        let r = submit(a, &token, &small_scene(&format!("load-{n}-{k}")));
                        assert_eq!(r.status, 202, "{}", r.text());
                        mine.push(r.json()["id"].as_str().unwrap().to_string());
                        continue;
                    }
                    let path = match roll {
                        15..=64 => format!("/jobs/{}", rng.pick(&mine)),
                        65..=84 => "/jobs?limit=20".to_string(),
                        _ => "/healthz".to_string(),
                    };
                    let t = Instant::now();
                    let r = call(a, "GET", &path, Some(&token), &[], b"");
                    gets.push(t.elapsed().as_secs_f64() * 1e3);
                    assert_eq!(r.status, 200, "{path}: {}", r.text());
                    if path.starts_with("/jobs?") {
                        // Only this key's jobs.
                        for j in ids(&r.json(), "jobs") {
                            assert!(mine.contains(&j), "client {n} sees job {j}");
                        }
                    }
                }
                gets
            })
        })
        .collect();
    let mut gets: Vec<f64> = handles
        .into_iter()
        .flat_map(|h| h.join().expect("client"))
        .collect();
    gets.sort_by(f64::total_cmp);
    let (p50, p99) = (percentile(&gets, 50.0), percentile(&gets, 99.0));
    eprintln!(
        "load with keys: {} GETs by {CLIENTS} keys, p50 {p50:.1} ms, p99 {p99:.1} ms, max {:.1} ms",
        gets.len(),
        gets.last().unwrap()
    );
    assert!(gets.len() > 200, "{} GETs", gets.len());
    assert!(p99 < 250.0, "GET p99 {p99:.1} ms");
}

/// With keys, the submission rate is counted per key, not per address: two keys on one
/// address have a burst each.
#[test]
fn submission_rate_is_per_key() {
    let dir = TempDir::new("auth-rate");
    let d = dir.0.to_str().unwrap();
    let store = ["--data-dir", d];
    let (k1, k2) = (add_key(&store, &["k1"]), add_key(&store, &["k2"]));
    let api = Proc::start(
        &dir.0,
        &[
            "--auth",
            "required",
            "--workers",
            "0",
            "--submit-rate",
            "0.01",
            "--submit-burst",
            "2",
        ],
    );
    let a = api.addr;
    for i in 0..2 {
        assert_eq!(submit(a, &k1, &small_scene(&format!("r1-{i}"))).status, 202);
    }
    let r = submit(a, &k1, &small_scene("r1-2"));
    assert_eq!(r.status, 429, "{}", r.text());
    assert_eq!(r.json()["type"], "/problems/rate-limited");
    assert!(r.header("retry-after").is_some());
    for i in 0..2 {
        assert_eq!(submit(a, &k2, &small_scene(&format!("r2-{i}"))).status, 202);
    }
    // Reads are not submissions.
    assert_eq!(call(a, "GET", "/jobs", Some(&k1), &[], b"").status, 200);
}

/// An API node on the PostgreSQL store `url` (no workers, keys required, no rate limit).
fn api_node(dir: &std::path::Path, url: &str) -> Proc {
    Proc::start(
        dir,
        &[
            "--store",
            url,
            "--node",
            "api",
            "--workers",
            "0",
            "--auth",
            "required",
            "--submit-rate",
            "0",
        ],
    )
}
