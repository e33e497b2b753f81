//! Hostile input to the real server binary on 127.0.0.1: request limits (body, JSON depth,
//! nodes, steps, stored bytes, submissions per client), path and id handling (nothing
//! outside the data directory is read or written), and a fuzz of the whole HTTP surface:
//! every answer is a 4xx (never a 5xx, never a hang) and the server stays healthy.

mod service_support;

use serde_json::json;
use service_support::*;
use std::path::Path;
use std::time::{Duration, Instant};

/// Request limits, each answered with its status and problem+json.
#[test]
fn limits_are_enforced_with_the_right_status() {
    let dir = TempDir::new("limits");
    let srv = Proc::start(
        &dir.0,
        &[
            "--workers",
            "1",
            "--max-body-bytes",
            "200000",
            "--max-json-depth",
            "8",
            "--max-nodes",
            "1000",
            "--max-steps",
            "500",
            "--max-stored-bytes",
            "1000000",
            "--submit-rate",
            "1000",
            "--submit-burst",
            "1000",
        ],
    );
    let a = srv.addr;
    // Body size: 413, problem+json, whatever the content.
    let big = vec![b' '; 200_001];
    let p = assert_problem(
        &http(
            a,
            "POST",
            "/jobs",
            &[("Content-Type", "application/json")],
            &big,
        ),
        413,
    );
    assert!(
        p["detail"].as_str().unwrap().contains("length limit"),
        "{p}"
    );
    // Just below the limit is read (and refused as malformed JSON, not as too large).
    let mut ok_size = vec![b' '; 199_990];
    ok_size.extend_from_slice(b"{\"a\": ");
    assert_problem(
        &http(
            a,
            "POST",
            "/jobs",
            &[("Content-Type", "application/json")],
            &ok_size,
        ),
        400,
    );
    // Nesting depth: 422 at the first value too deep; beyond serde_json's own limit 400.
    let mut s = small_scene("deep");
    s["loads"]["f0"] = json!([[[[[[[[[[1]]]]]]]]], 0]);
    let p = assert_problem(&post_json(a, "/jobs", &s), 422);
    assert!(p["errors"][0]["pointer"]
        .as_str()
        .unwrap()
        .starts_with("/loads/f0/0/0/0/0/0/0"));
    let deep = format!("{}{}", "[".repeat(100_000), "]".repeat(100_000));
    assert_problem(
        &http(
            a,
            "POST",
            "/jobs",
            &[("Content-Type", "application/json")],
            deep.as_bytes(),
        ),
        400,
    );
    // Nodes, steps, stored bytes: 422 at the field responsible.
    let mut s = small_scene("nodes");
    s["mesh"]["h"] = json!("1/64");
    let p = assert_problem(&post_json(a, "/jobs", &s), 422);
    assert_eq!(p["errors"][0]["pointer"], "/mesh/h");
    let mut s = small_scene("steps");
    s["time"] = json!({"t_end": 1, "N": 501});
    let p = assert_problem(&post_json(a, "/jobs", &s), 422);
    assert_eq!(p["errors"][0]["pointer"], "/time/k");
    let mut s = small_scene("stored");
    s["mesh"]["h"] = json!("1/16");
    s["time"] = json!({"t_end": 1, "N": 500});
    s["output"]["every"] = json!(1);
    let p = assert_problem(&post_json(a, "/jobs", &s), 422);
    assert_eq!(p["errors"][0]["pointer"], "/output");
    // Formula length is capped by the scene validation (422 at the formula).
    let mut s = small_scene("formula");
    s["loads"]["f0"] = json!([0, format!("0{}", "+0".repeat(2000))]);
    let p = assert_problem(&post_json(a, "/jobs", &s), 422);
    assert!(
        p["errors"].to_string().contains("/loads/f0/1"),
        "{}",
        p["errors"]
    );
    // A valid small job still goes through.
    assert_eq!(post_json(a, "/jobs", &small_scene("fine")).status, 202);
}

/// Submissions per client: a token bucket per peer IP, 429 + Retry-After beyond; reads and
/// cancellations are not counted.
#[test]
fn submissions_are_rate_limited_per_client() {
    let dir = TempDir::new("rate");
    let srv = Proc::start(
        &dir.0,
        &[
            "--workers",
            "0",
            // One token every 2 s: the requests below that must find the bucket empty
            // have that long, even on a loaded machine.
            "--submit-rate",
            "0.5",
            "--submit-burst",
            "3",
        ],
    );
    let a = srv.addr;
    let mut ids = Vec::new();
    for i in 0..3 {
        let r = post_json(a, "/jobs", &small_scene(&format!("rate-{i}")));
        assert_eq!(r.status, 202, "{}", r.text());
        ids.push(r.json()["id"].as_str().unwrap().to_string());
    }
    let r = post_json(a, "/jobs", &small_scene("rate-3"));
    let p = assert_problem(&r, 429);
    assert_eq!(p["type"], "/problems/rate-limited");
    assert_eq!(r.header("retry-after"), Some("2"));
    // Malformed submissions are refused before they are read, as the limit is reached.
    assert_problem(
        &http(
            a,
            "POST",
            "/jobs",
            &[("Content-Type", "application/json")],
            b"{",
        ),
        429,
    );
    // Reads and cancellations are not submissions.
    for _ in 0..20 {
        assert_eq!(get(a, "/healthz").status, 200);
        assert_eq!(get(a, &format!("/jobs/{}", ids[0])).status, 200);
    }
    assert_eq!(
        http(a, "POST", &format!("/jobs/{}/cancel", ids[0]), &[], b"").status,
        202
    );
    // After the advertised wait, the bucket has a token again.
    std::thread::sleep(Duration::from_millis(2100));
    let r = post_json(a, "/jobs", &small_scene("rate-4"));
    assert_eq!(r.status, 202, "{}", r.text());
    let metrics = get(a, "/metrics").text();
    assert!(
        metrics.contains("contact_sim_jobs{status=\"queued\"} 3"),
        "{metrics}"
    );
    // Other clients (other loopback addresses) have buckets of their own.
    let me: std::net::IpAddr = "127.0.0.1".parse().unwrap();
    let ct = [("Content-Type", "application/json")];
    while try_http_from(me, a, "POST", "/jobs", &ct, b"{")
        .unwrap()
        .status
        != 429
    {}
    for (i, other) in ["127.0.0.2", "127.0.0.3"].iter().enumerate() {
        let other: std::net::IpAddr = other.parse().unwrap();
        for k in 0..3 {
            let body = small_scene(&format!("rate-other-{i}-{k}")).to_string();
            let r = try_http_from(other, a, "POST", "/jobs", &ct, body.as_bytes()).unwrap();
            assert_eq!(r.status, 202, "{other}: {}", r.text());
        }
        let r = try_http_from(other, a, "POST", "/jobs", &ct, b"{}").unwrap();
        assert_problem(&r, 429);
    }
    assert_problem(
        &try_http_from(me, a, "POST", "/jobs", &ct, b"{").unwrap(),
        429,
    );
}

/// Every file under `dir` (relative path, size), sorted.
fn tree(dir: &Path) -> Vec<(String, u64)> {
    fn walk(base: &Path, d: &Path, out: &mut Vec<(String, u64)>) {
        for e in std::fs::read_dir(d).unwrap().flatten() {
            let p = e.path();
            let rel = p.strip_prefix(base).unwrap().to_string_lossy().into_owned();
            if e.file_type().unwrap().is_dir() {
                out.push((format!("{rel}/"), 0));
                walk(base, &p, out);
            } else {
                out.push((rel, e.metadata().unwrap().len()));
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out);
    out.sort();
    out
}

/// Ids and file names that try to leave the data directory are all refused (4xx); the
/// secrets next to the data directory never appear in a response, and no file appears or
/// changes outside it.
#[test]
fn no_path_escapes_the_data_dir() {
    let base = TempDir::new("paths");
    let data = base.0.join("data");
    const SECRET: &str = "TOP-SECRET-CONTENT-0123456789";
    for name in ["secret", "secret.vtu", "summary.json", "1.vtu", "last.vtu"] {
        std::fs::write(base.0.join(name), SECRET).unwrap();
    }
    std::fs::create_dir_all(base.0.join("results")).unwrap();
    std::fs::write(base.0.join("results").join("summary.json"), SECRET).unwrap();
    let srv = Proc::start(&data, &["--workers", "1"]);
    let a = srv.addr;
    let r = post_json(a, "/jobs", &small_scene("paths"));
    assert_eq!(r.status, 202);
    let id = r.json()["id"].as_str().unwrap().to_string();
    wait_status(a, &id, &["succeeded"], Duration::from_secs(60));
    let outside_before = tree(&base.0)
        .into_iter()
        .filter(|(p, _)| !p.starts_with("data"))
        .collect::<Vec<_>>();

    let long = "a".repeat(5000);
    let very_long = "b".repeat(70_000);
    let hostile_ids = [
        "..",
        "..%2F..%2Fsecret",
        "%2E%2E",
        "%2e%2e%2f%2e%2e%2fsecret",
        "..%5C..%5Csecret",
        "%2Fetc%2Fpasswd",
        "%00",
        &format!("{id}%00"),
        &format!("{id}%2F..%2F..%2F..%2Fsecret"),
        &format!("..%2F{id}"),
        "00000000-0000-0000-0000-000000000000",
        "%FF%FE",
        "~",
        &long,
    ];
    let hostile_files = [
        "..%2F..%2F..%2Fsecret.vtu",
        "..%2F..%2Fsummary.json",
        "..%2Fsummary.json",
        "%2E%2E%2F%2E%2E%2F1.vtu",
        "%2Fetc%2Fpasswd",
        "%2Fetc%2Fpasswd.vtu",
        &format!("{}%2Fsecret.vtu", base.0.display()).replace('/', "%2F"),
        "1.vtu%00",
        "1%00.vtu",
        "%00.vtu",
        "step_000001.bin",
        "summary.json",
        "reports.json",
        "..",
        ".vtu",
        "-1.vtu",
        "1.0.vtu",
        "1e3.vtu",
        "0x1.vtu",
        "99999999999999999999999999.vtu",
        "last.vtu.vtu",
        "%FF.vtu",
        "..%5Csecret.vtu",
        &format!("{long}.vtu"),
        &very_long,
    ];
    let mut requests: Vec<(String, String)> = Vec::new();
    let suffixes = [
        "",
        "/summary",
        "/mesh",
        "/fields",
        "/fields/1.vtu",
        "/result.pvd",
        "/archive.tar",
        "/events",
    ];
    for hid in &hostile_ids {
        for s in suffixes {
            requests.push(("GET".into(), format!("/jobs/{hid}{s}")));
        }
        requests.push(("DELETE".into(), format!("/jobs/{hid}")));
        requests.push(("POST".into(), format!("/jobs/{hid}/cancel")));
    }
    for f in &hostile_files {
        requests.push(("GET".into(), format!("/jobs/{id}/fields/{f}")));
    }
    for q in [
        "step=..%2F..%2Fsecret",
        "step=%2Fetc%2Fpasswd",
        "step=1%00",
        "step=-1",
        "step=99999999999999999999",
        "fields=..%2Fsecret",
        "fields=u%00",
    ] {
        requests.push(("GET".into(), format!("/jobs/{id}/fields?{q}")));
    }
    // Raw paths that are not normalised by the client.
    for p in [
        "/jobs/../../secret",
        "/jobs/./../secret",
        "//etc/passwd",
        "/../secret",
        "/jobs/%2e%2e/%2e%2e/secret",
        &format!("/jobs/{id}/../../secret"),
        &format!("/jobs/{id}/fields/../../../secret.vtu"),
        &format!("/jobs/{id}/fields/..\\..\\secret.vtu"),
    ] {
        requests.push(("GET".into(), p.to_string()));
    }
    // Other spellings of the same UUID name the same job (the directory name is always
    // formatted from the parsed id, so they reach nothing else).
    for alias in [
        id.to_uppercase(),
        format!("{{{id}}}"),
        format!("urn:uuid:{id}"),
        id.replace('-', ""),
    ] {
        let r = get(a, &format!("/jobs/{alias}"));
        assert_eq!(r.status, 200, "{alias}");
        assert_eq!(r.json()["id"], id.as_str());
    }
    // Sent as raw bytes: the request targets are hostile by design, and no client may
    // normalise or refuse them.
    let mut statuses = std::collections::BTreeMap::new();
    for (m, path) in &requests {
        let r = raw_request(a, m, path, &[], b"", Duration::from_secs(30))
            .unwrap_or_else(|e| panic!("{m} {path}: {e}"));
        assert!(
            (400..500).contains(&r.status),
            "{m} {path}: {} {}",
            r.status,
            r.text()
        );
        assert!(!r.text().contains(SECRET), "{m} {path} leaked the secret");
        *statuses.entry(r.status).or_insert(0) += 1;
    }
    eprintln!("{} traversal requests: {statuses:?}", requests.len());
    // The job is intact and still served; nothing changed outside the data directory.
    assert_eq!(get(a, &format!("/jobs/{id}")).json()["status"], "succeeded");
    assert_eq!(get(a, &format!("/jobs/{id}/fields/last.vtu")).status, 200);
    drop(srv);
    let outside_after = tree(&base.0)
        .into_iter()
        .filter(|(p, _)| !p.starts_with("data"))
        .collect::<Vec<_>>();
    assert_eq!(outside_before, outside_after);
    for name in ["secret", "secret.vtu", "summary.json", "1.vtu", "last.vtu"] {
        assert_eq!(std::fs::read_to_string(base.0.join(name)).unwrap(), SECRET);
    }
    // Inside the data directory: the store, the (empty) directory of uploaded meshes, and
    // the one job's directory of result files.
    for (p, _) in tree(&data) {
        let ok = p.starts_with("jobs.sqlite3")
            || p == "meshes/"
            || p == "results/"
            || p.starts_with(&format!("results/{id}"));
        assert!(ok, "unexpected file {p} in the data directory");
    }
}

/// Malformed requests of every kind: always 4xx (or a closed connection for bytes that are
/// not HTTP), never 5xx, never a hang; the server answers /healthz throughout.
#[test]
fn fuzz_the_http_surface() {
    let dir = TempDir::new("fuzz");
    let srv = Proc::start(
        &dir.0,
        &[
            "--workers",
            "1",
            "--max-nodes",
            "2000",
            "--submit-rate",
            "100000",
            "--submit-burst",
            "100000",
        ],
    );
    let a = srv.addr;
    let r = post_json(a, "/jobs", &small_scene("fuzz-base"));
    let id = r.json()["id"].as_str().unwrap().to_string();
    wait_status(a, &id, &["succeeded"], Duration::from_secs(60));
    let t0 = Instant::now();
    let mut rng = Rng::seeded(0x5eed_1234_abcd_ef01);
    let timeout = Duration::from_secs(20);
    let mut sent = 0usize;
    let mut statuses = std::collections::BTreeMap::<u16, usize>::new();
    let mut closed = 0usize;
    let mut check = |what: &str, r: Result<Resp, String>, allow_ok: bool| {
        sent += 1;
        match r {
            Ok(r) => {
                *statuses.entry(r.status).or_default() += 1;
                assert!(r.status < 500, "{what}: {} {}", r.status, r.text());
                if !allow_ok {
                    assert!(r.status >= 400, "{what}: {} {}", r.status, r.text());
                }
                if r.status >= 400 && r.header("content-type").is_some() {
                    // Errors from the application are problem+json (hyper's own parse
                    // errors carry no body).
                    assert_eq!(
                        r.header("content-type"),
                        Some("application/problem+json"),
                        "{what}: {}",
                        r.text()
                    );
                }
            }
            Err(e) if e.starts_with("no header end in \"\"") => closed += 1,
            Err(e) => panic!("{what}: {e}"),
        }
    };
    let json_ct = [("Content-Type", "application/json")];

    // 1. Random bytes as the JSON body of a submission.
    for i in 0..1000 {
        let n = rng.below(if i % 10 == 0 { 100_000 } else { 400 });
        let body = rng.bytes(n);
        check(
            "random body",
            try_http(a, "POST", "/jobs", &json_ct, &body, timeout),
            false,
        );
    }
    // 2. Mutated scenes: valid JSON, wrong shapes/values.
    let base = serde_json::to_string(&small_scene("fuzz")).unwrap();
    let tokens: [&[u8]; 14] = [
        b"null",
        b"1e999",
        b"-1e308",
        b"\"NaN\"",
        b"\"Infinity\"",
        b"[]",
        b"{}",
        b"\"\"",
        b"true",
        b"0",
        b"-0",
        b"18446744073709551616",
        b"\"1/0\"",
        b"\"x/(x-x)\"",
    ];
    for _ in 0..1000 {
        let mut body = base.clone().into_bytes();
        for _ in 0..1 + rng.below(3) {
            let at = rng.below(body.len());
            match rng.below(4) {
                0 => {
                    body.remove(at);
                }
                1 => body.insert(at, *rng.pick(b"{}[]\",:0.-e\\")),
                2 => body[at] = rng.next() as u8,
                _ => {
                    // Replace a number or string value with a hostile token.
                    let t = *rng.pick(&tokens);
                    let end = (at + 1 + rng.below(8)).min(body.len());
                    body.splice(at..end, t.iter().copied());
                }
            }
        }
        // A mutation may leave the scene valid (a new job): 202 is allowed then.
        check(
            "mutated scene",
            try_http(a, "POST", "/jobs", &json_ct, &body, timeout),
            true,
        );
    }
    // 3. Wrong or odd content types (some are not valid header values: sent raw).
    for ct in [
        "text/plain",
        "application/xml",
        "multipart/form-data; boundary=x",
        "application/x-www-form-urlencoded",
        "",
        "application/json; charset=utf-16",
        "\u{1}",
        "application/jsonx",
    ] {
        check(
            "content type",
            raw_request(
                a,
                "POST",
                "/jobs",
                &[("Content-Type", ct)],
                b"{\"preset\": \"nope\"}",
                timeout,
            ),
            false,
        );
    }
    // 4. Huge and odd headers.
    let huge = "x".repeat(1 << 20);
    let many: Vec<(String, String)> = (0..300).map(|i| (format!("X-H{i}"), "v".into())).collect();
    let many_ref: Vec<(&str, &str)> = many.iter().map(|(k, v)| (k.as_str(), v.as_str())).collect();
    check(
        "huge header",
        raw_request(a, "GET", "/healthz", &[("X-Big", &huge)], b"", timeout),
        false,
    );
    check(
        "many headers",
        raw_request(a, "GET", "/healthz", &many_ref, b"", timeout),
        false,
    );
    check(
        "huge idempotency key",
        try_http(
            a,
            "POST",
            "/jobs",
            &[
                ("Content-Type", "application/json"),
                ("Idempotency-Key", &"k".repeat(10_000)),
            ],
            base.as_bytes(),
            timeout,
        ),
        false,
    );
    check(
        "non-ASCII idempotency key",
        raw(
            a,
            format!(
                "POST /jobs HTTP/1.1\r\nHost: t\r\nConnection: close\r\nContent-Type: application/json\r\nIdempotency-Key: \u{e9}\u{ff}\r\nContent-Length: {}\r\n\r\n{base}",
                base.len()
            )
            .as_bytes(),
            timeout,
        ),
        false,
    );
    check(
        "bad content length",
        raw(
            a,
            b"POST /jobs HTTP/1.1\r\nHost: t\r\nContent-Length: -5\r\n\r\n{}",
            timeout,
        ),
        false,
    );
    check(
        "two content lengths",
        raw(
            a,
            b"POST /jobs HTTP/1.1\r\nHost: t\r\nContent-Length: 2\r\nContent-Length: 3\r\n\r\n{}",
            timeout,
        ),
        false,
    );
    check(
        "bad chunked body",
        raw(
            a,
            b"POST /jobs HTTP/1.1\r\nHost: t\r\nContent-Type: application/json\r\nTransfer-Encoding: chunked\r\n\r\nzz\r\n{}\r\n0\r\n\r\n",
            timeout,
        ),
        false,
    );
    // 5. Bad query strings (as sent: no client re-encodes them).
    for q in [
        "limit=0",
        "limit=-1",
        "limit=501",
        "limit=1e3",
        "limit=%FF",
        "limit",
        "status=QUEUED",
        "status=%00",
        "cursor=x",
        "cursor=s0",
        "cursor=s99999999999999999999999",
        "cursor=%",
        "a=1&b=2",
        "&&&=&=",
        "%%%%",
        "status[]=queued",
    ] {
        check(
            "bad query",
            raw_request(a, "GET", &format!("/jobs?{q}"), &[], b"", timeout),
            false,
        );
    }
    for q in [
        "step=x",
        "step=",
        "mesh=2",
        "fields=u,,p",
        "step=1&step=2&x=1",
        "step=%FF",
    ] {
        check(
            "bad fields query",
            raw_request(
                a,
                "GET",
                &format!("/jobs/{id}/fields?{q}"),
                &[],
                b"",
                timeout,
            ),
            false,
        );
    }
    // 6. Unknown routes and bad UUIDs (raw request targets).
    for p in [
        "/client/",
        "/client/nope.js",
        "/client/..%2F..%2Fsecret",
        "/client/%2e%2e/app.js",
        "/jobs/",
        "/job",
        "/jobs/x/y/z",
        "/presets/",
        "/presets/%00",
        "/presets/..%2F..%2Fsecret",
        "/metrics/x",
        "/JOBS",
        "/jobs/00000000-0000-0000-0000-00000000000g",
        "/jobs/0000000000000000000000000000000000000",
        "/jobs/%FF",
        "/%FF%FE",
        "*",
    ] {
        check(
            "unknown route",
            raw_request(a, "GET", p, &[], b"", timeout),
            false,
        );
    }
    // 7. Every method, standard or not, on every route (allowed methods may succeed, the rest
    // are 405).
    let routes = [
        "/jobs".to_string(),
        format!("/jobs/{id}"),
        format!("/jobs/{id}/cancel"),
        format!("/jobs/{id}/events"),
        format!("/jobs/{id}/summary"),
        format!("/jobs/{id}/mesh"),
        format!("/jobs/{id}/fields"),
        format!("/jobs/{id}/fields/last.vtu"),
        format!("/jobs/{id}/result.pvd"),
        format!("/jobs/{id}/archive.tar"),
        format!("/jobs/{id}/report.svg"),
        "/meshes".to_string(),
        format!("/meshes/{}", "0".repeat(64)),
        format!("/meshes/{}/file", "0".repeat(64)),
        "/".to_string(),
        "/client/app.js".to_string(),
        "/presets".to_string(),
        "/presets/paper-exp1".to_string(),
        "/healthz".to_string(),
        "/metrics".to_string(),
        "/openapi.yaml".to_string(),
    ];
    for route in &routes {
        for m in [
            "GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS", "TRACE", "CONNECT", "BREW",
            "get",
        ] {
            // DELETE of the job would remove it: exercise it last, separately.
            if m == "DELETE" && route == &format!("/jobs/{id}") {
                continue;
            }
            let body: &[u8] = if m == "POST" { b"{}" } else { b"" };
            let r = if m == "HEAD" {
                // No body follows a HEAD answer: read headers only.
                raw_head(a, route)
            } else {
                raw_request(a, m, route, &json_ct, body, timeout)
            };
            check(&format!("{m} {route}"), r, true);
        }
    }
    // 8. Bytes that are not HTTP at all.
    for i in 0..200 {
        let n = 1 + rng.below(3000);
        let mut b = rng.bytes(n);
        if i % 2 == 0 {
            b.extend_from_slice(b"\r\n\r\n");
        }
        check("not HTTP", raw_eof(a, &b, timeout), false);
    }
    // The server is healthy and still serves the job's results.
    let health = get(a, "/healthz");
    assert_eq!(health.status, 200);
    assert_eq!(get(a, &format!("/jobs/{id}/summary")).status, 200);
    assert_eq!(
        http(a, "DELETE", &format!("/jobs/{id}"), &[], b"").status,
        204
    );
    eprintln!(
        "fuzz: {sent} requests in {:.1} s, statuses {statuses:?}, {closed} closed without an answer",
        t0.elapsed().as_secs_f64()
    );
    assert!(srv.log.lock().unwrap().is_empty() || !srv.log.lock().unwrap().contains("panicked"));
}

/// HEAD: the response has headers only.
fn raw_head(a: std::net::SocketAddr, path: &str) -> Result<Resp, String> {
    raw(
        a,
        format!("HEAD {path} HTTP/1.1\r\nHost: t\r\nConnection: close\r\n\r\n").as_bytes(),
        Duration::from_secs(20),
    )
}

/// A client that sends its request head too slowly, or nothing at all, is disconnected
/// after `--header-timeout`; other clients are served meanwhile, and a long-lived event
/// stream (head sent at once) is not cut.
#[test]
fn slow_and_silent_clients_are_disconnected() {
    use std::io::{Read, Write};
    let dir = TempDir::new("slow");
    let srv = Proc::start(&dir.0, &["--workers", "0", "--header-timeout", "1"]);
    let a = srv.addr;
    let id = post_json(a, "/jobs", &small_scene("slow")).json()["id"]
        .as_str()
        .unwrap()
        .to_string();
    // Bytes read until the server closes (or 10 s pass: then it did not); the time is
    // counted from the connection.
    let start = Instant::now();
    let until_closed = |mut s: std::net::TcpStream| -> (Duration, Vec<u8>) {
        s.set_read_timeout(Some(Duration::from_millis(100)))
            .unwrap();
        let (got, _) = read_until_closed(&mut s, start + Duration::from_secs(10));
        (start.elapsed(), got)
    };
    // Silent: connects and sends nothing.
    let silent = std::net::TcpStream::connect(a).unwrap();
    // Slow loris: a header line every 300 ms, never the blank line.
    let mut slow = std::net::TcpStream::connect(a).unwrap();
    slow.write_all(b"GET /healthz HTTP/1.1\r\nHost: t\r\n")
        .unwrap();
    let feeder = {
        let mut s = slow.try_clone().unwrap();
        std::thread::spawn(move || {
            for i in 0..30 {
                if s.write_all(format!("X-Slow-{i}: 1\r\n").as_bytes())
                    .is_err()
                {
                    return i;
                }
                std::thread::sleep(Duration::from_millis(300));
            }
            30
        })
    };
    // An event stream that stays open longer than the header timeout.
    let mut sse = std::net::TcpStream::connect(a).unwrap();
    sse.write_all(format!("GET /jobs/{id}/events HTTP/1.1\r\nHost: t\r\n\r\n").as_bytes())
        .unwrap();
    // Others are served meanwhile.
    for _ in 0..10 {
        assert_eq!(get(a, "/healthz").status, 200);
    }
    let (t_silent, _) = until_closed(silent);
    let (t_slow, got) = until_closed(slow);
    let lines_sent = feeder.join().unwrap();
    assert!(
        t_silent < Duration::from_secs(5),
        "silent client kept {t_silent:?}"
    );
    assert!(
        t_slow < Duration::from_secs(5),
        "slow client kept {t_slow:?}"
    );
    assert!(lines_sent < 30, "the slow client was never cut off");
    let got = String::from_utf8_lossy(&got);
    assert!(got.is_empty() || got.starts_with("HTTP/1.1 408"), "{got}");
    // The event stream is still open after more than the header timeout.
    sse.set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let t = Instant::now();
    let mut buf = [0u8; 4096];
    let mut head = Vec::new();
    while t.elapsed() < Duration::from_millis(1500) {
        match sse.read(&mut buf) {
            Ok(0) => panic!("event stream closed after {:?}", t.elapsed()),
            Ok(n) => head.extend_from_slice(&buf[..n]),
            Err(_) => {}
        }
    }
    assert!(String::from_utf8_lossy(&head).starts_with("HTTP/1.1 200"));
    assert_eq!(get(a, "/healthz").status, 200);
    eprintln!(
        "slow clients: silent one disconnected after {:.1} s, slow loris after {:.1} s ({lines_sent} header lines)",
        t_silent.as_secs_f64(),
        t_slow.as_secs_f64()
    );
}
