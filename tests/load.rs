//! Load test against the real server binary on 127.0.0.1 (bounded: about 20 s of load).
//!
//! The workers are saturated with long jobs while many concurrent clients submit small
//! jobs, poll them, list jobs, follow their event streams and cancel some. Asserted:
//! GET latency p99 stays low (the numerics never starves the async runtime), no request
//! fails with a 5xx or hangs, no accepted job is lost or duplicated (every accepted id
//! reaches a final state exactly once, was claimed once, and the store's counts match),
//! and the server's memory stays bounded. The figures are printed (README, Reliability).

mod service_support;

use serde_json::Value;
use service_support::*;
use std::collections::{HashMap, HashSet};
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

const CLIENTS: usize = 16;
const LOAD: Duration = Duration::from_secs(20);
const P99_BOUND_MS: f64 = 250.0;
const RSS_BOUND_MIB: u64 = 600;

#[derive(Default)]
struct Tally {
    get_ms: Vec<f64>,
    post_ms: Vec<f64>,
    accepted: Vec<String>,
    cancels: usize,
    sse_streams: usize,
    sse_events: usize,
    requests: usize,
    statuses: HashMap<u16, usize>,
}

/// How many events the stream of `id` delivered within `for_`.
fn sse(a: SocketAddr, id: &str, for_: Duration) -> Result<usize, String> {
    let text = sse_text(a, id, for_)?;
    Ok(text.lines().filter(|l| l.starts_with("event: ")).count())
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((p / 100.0) * (sorted.len() - 1) as f64).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

fn client(a: SocketAddr, n: usize, deadline: Instant, tally: Arc<Mutex<Tally>>) {
    let mut rng = Rng::seeded(0x1234_5678 + n as u64 * 0x9e37_79b9);
    let mut mine: Vec<String> = Vec::new();
    let mut local = Tally::default();
    let timeout = Duration::from_secs(30);
    let mut k = 0;
    while Instant::now() < deadline {
        let roll = rng.below(100);
        let t = Instant::now();
        let (what, r) = if roll < 20 || mine.is_empty() {
            k += 1;
            let scene = small_scene(&format!("load-{n}-{k}"));
            let r = try_post_json(a, "/jobs", &scene, timeout);
            local.post_ms.push(t.elapsed().as_secs_f64() * 1e3);
            if let Ok(r) = &r {
                assert_eq!(r.status, 202, "submit: {}", r.text());
                mine.push(r.json()["id"].as_str().unwrap().to_string());
                local.accepted.push(mine.last().unwrap().clone());
            }
            ("submit", r)
        } else if roll < 60 {
            let id = rng.pick(&mine).clone();
            (
                "poll",
                try_http(a, "GET", &format!("/jobs/{id}"), &[], b"", timeout),
            )
        } else if roll < 70 {
            (
                "list",
                try_http(a, "GET", "/jobs?limit=20", &[], b"", timeout),
            )
        } else if roll < 75 {
            ("health", try_http(a, "GET", "/healthz", &[], b"", timeout))
        } else if roll < 80 {
            ("metrics", try_http(a, "GET", "/metrics", &[], b"", timeout))
        } else if roll < 90 {
            let id = rng.pick(&mine).clone();
            let events = sse(a, &id, Duration::from_millis(300 + rng.below(700) as u64))
                .unwrap_or_else(|e| panic!("client {n}: {e}"));
            local.sse_streams += 1;
            local.sse_events += events;
            local.requests += 1;
            continue;
        } else {
            let id = rng.pick(&mine).clone();
            let r = try_http(a, "POST", &format!("/jobs/{id}/cancel"), &[], b"", timeout);
            if let Ok(r) = &r {
                // 202 (queued → cancelled or running → asked) or 409 (already finished).
                assert!(r.status == 202 || r.status == 409, "cancel: {}", r.text());
                local.cancels += 1;
            }
            ("cancel", r)
        };
        let ms = t.elapsed().as_secs_f64() * 1e3;
        let r = r.unwrap_or_else(|e| panic!("client {n} {what}: {e}"));
        assert!(
            r.status < 500,
            "client {n} {what}: {} {}",
            r.status,
            r.text()
        );
        if what != "submit" && what != "cancel" {
            assert_eq!(r.status, 200, "{what}: {}", r.text());
            local.get_ms.push(ms);
        }
        *local.statuses.entry(r.status).or_default() += 1;
        local.requests += 1;
    }
    let mut t = tally.lock().unwrap();
    t.get_ms.extend(local.get_ms);
    t.post_ms.extend(local.post_ms);
    t.accepted.extend(local.accepted);
    t.cancels += local.cancels;
    t.sse_streams += local.sse_streams;
    t.sse_events += local.sse_events;
    t.requests += local.requests;
    for (s, c) in local.statuses {
        *t.statuses.entry(s).or_default() += c;
    }
}

#[test]
fn load_with_saturated_workers() {
    let dir = TempDir::new("load");
    let workers = 2;
    let srv = Proc::start(
        &dir.0,
        &[
            "--workers",
            &workers.to_string(),
            "--submit-rate",
            "0",
            "--max-steps",
            "10000000",
            "--queue-capacity",
            "100000",
        ],
    );
    let a = srv.addr;
    let pid = srv.pid();
    let (rss0, _) = rss_kib(pid).unwrap();

    // Saturate every worker with a long job (cancelled after the load phase).
    let long: Vec<String> = (0..workers)
        .map(|i| {
            let r = post_json(
                a,
                "/jobs",
                &long_scene(&format!("long-{i}"), 16, 5_000_000, 4),
            );
            assert_eq!(r.status, 202, "{}", r.text());
            r.json()["id"].as_str().unwrap().to_string()
        })
        .collect();
    for id in &long {
        wait_status(a, id, &["running"], Duration::from_secs(60));
    }

    // Memory sampler.
    let stop = Arc::new(AtomicBool::new(false));
    let peak_rss = Arc::new(AtomicU64::new(rss0));
    let sampler = {
        let (stop, peak) = (stop.clone(), peak_rss.clone());
        std::thread::spawn(move || {
            while !stop.load(Ordering::Relaxed) {
                if let Some((rss, _)) = rss_kib(pid) {
                    peak.fetch_max(rss, Ordering::Relaxed);
                }
                std::thread::sleep(Duration::from_millis(100));
            }
        })
    };

    let t0 = Instant::now();
    let deadline = t0 + LOAD;
    let tally = Arc::new(Mutex::new(Tally::default()));
    let handles: Vec<_> = (0..CLIENTS)
        .map(|n| {
            let tally = tally.clone();
            std::thread::spawn(move || client(a, n, deadline, tally))
        })
        .collect();
    for h in handles {
        h.join().expect("client thread");
    }
    let load_s = t0.elapsed().as_secs_f64();
    // The workers were busy with the long jobs throughout.
    for id in &long {
        assert_eq!(get(a, &format!("/jobs/{id}")).json()["status"], "running");
    }
    let steps_during_load: u64 = get(a, "/metrics")
        .text()
        .lines()
        .find_map(|l| l.strip_prefix("contact_sim_steps_total "))
        .unwrap()
        .parse()
        .unwrap();

    // Release the workers; every accepted job must reach a final state.
    for id in &long {
        assert_eq!(
            http(a, "POST", &format!("/jobs/{id}/cancel"), &[], b"").status,
            202
        );
    }
    let mut t = std::mem::take(&mut *tally.lock().unwrap());
    let accepted: HashSet<String> = t.accepted.iter().cloned().collect();
    assert_eq!(
        accepted.len(),
        t.accepted.len(),
        "an id was handed out twice"
    );
    let drain0 = Instant::now();
    let mut finals: HashMap<String, Value> = HashMap::new();
    for id in t.accepted.iter().chain(&long) {
        let j = wait_status(
            a,
            id,
            &["succeeded", "failed", "cancelled"],
            Duration::from_secs(180),
        );
        finals.insert(id.clone(), j);
    }
    let drain_s = drain0.elapsed().as_secs_f64();
    stop.store(true, Ordering::Relaxed);
    sampler.join().unwrap();
    let (rss_end, hwm) = rss_kib(pid).unwrap();

    // Every job listed exactly once; the store's counts match what the clients saw.
    let mut listed: Vec<String> = Vec::new();
    let mut next = Some("/jobs?limit=500".to_string());
    while let Some(url) = next {
        let page = get(a, &url).json();
        listed.extend(
            page["jobs"]
                .as_array()
                .unwrap()
                .iter()
                .map(|j| j["id"].as_str().unwrap().to_string()),
        );
        next = page["next"].as_str().map(String::from);
    }
    let listed_set: HashSet<&String> = listed.iter().collect();
    assert_eq!(listed_set.len(), listed.len(), "a job is listed twice");
    assert_eq!(
        listed.len(),
        t.accepted.len() + long.len(),
        "jobs lost or added"
    );
    assert!(finals.keys().all(|id| listed_set.contains(id)));
    let mut by_status: HashMap<String, usize> = HashMap::new();
    for (id, j) in &finals {
        let s = j["status"].as_str().unwrap().to_string();
        assert!(s != "failed", "job {id} failed: {j}");
        // Claimed at most once: no job was run twice.
        assert!(
            j["attempt"].as_u64().unwrap() <= 1,
            "job {id} ran twice: {j}"
        );
        if s == "succeeded" {
            assert_eq!(j["attempt"], 1);
        }
        *by_status.entry(s).or_default() += 1;
    }
    let metrics = get(a, "/metrics").text();
    for (s, n) in &by_status {
        assert!(
            metrics.contains(&format!("contact_sim_jobs{{status=\"{s}\"}} {n}\n")),
            "{s} = {n}: {metrics}"
        );
    }
    assert!(metrics.contains("contact_sim_queue_depth 0\n"));
    // A sample of the succeeded small jobs have complete results.
    for (id, _) in finals
        .iter()
        .filter(|(_, j)| j["status"] == "succeeded")
        .take(20)
    {
        let s = get(a, &format!("/jobs/{id}/summary")).json();
        assert_eq!(s["steps"].as_array().unwrap().len(), 4);
    }

    t.get_ms.sort_by(f64::total_cmp);
    t.post_ms.sort_by(f64::total_cmp);
    let (p50, p99, max) = (
        percentile(&t.get_ms, 50.0),
        percentile(&t.get_ms, 99.0),
        t.get_ms.last().copied().unwrap_or(0.0),
    );
    let peak = peak_rss.load(Ordering::Relaxed);
    eprintln!(
        "load: {CLIENTS} clients for {load_s:.1} s with {workers} workers saturated \
         ({steps_during_load} time steps computed meanwhile)\n\
         load: {} requests ({:.0}/s): {} GETs p50 {p50:.2} ms, p99 {p99:.2} ms, max {max:.1} ms; \
         {} submissions p50 {:.2} ms, p99 {:.2} ms; {} SSE streams ({} events); {} cancels\n\
         load: statuses {:?}\n\
         load: {} jobs accepted, final {:?}, lost 0, duplicated 0; drained in {drain_s:.1} s\n\
         load: server RSS {} MiB at start, peak {} MiB during load (VmHWM {} MiB), {} MiB at end",
        t.requests,
        t.requests as f64 / load_s,
        t.get_ms.len(),
        t.post_ms.len(),
        percentile(&t.post_ms, 50.0),
        percentile(&t.post_ms, 99.0),
        t.sse_streams,
        t.sse_events,
        t.cancels,
        {
            let mut v: Vec<_> = t.statuses.iter().collect();
            v.sort();
            v
        },
        t.accepted.len() + long.len(),
        by_status,
        rss0 >> 10,
        peak >> 10,
        hwm >> 10,
        rss_end >> 10,
    );
    assert!(t.get_ms.len() > 500, "too few requests to measure");
    assert!(p99 < P99_BOUND_MS, "GET p99 {p99:.1} ms");
    assert!(hwm >> 10 < RSS_BOUND_MIB, "peak RSS {} MiB", hwm >> 10);
}
