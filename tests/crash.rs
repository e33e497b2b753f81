//! Crash test: the real server binary is killed with SIGKILL at random moments, in the
//! middle of runs and of result writes, and restarted on the same data directory, over
//! several rounds. Asserted: every accepted job ends succeeded (finished, or re-queued and
//! then finished), and every served result is complete and consistent: the summary parses
//! and has every step, every stored step file decodes (checksums) and is the step it is
//! named after, the stored steps are exactly the scene's output selection, no temporary
//! file survives, and a job interrupted by crashes ends with the same numbers as an
//! uninterrupted run (bit for bit). A sweep whose member is running when the server is
//! killed completes after the restart, its killed member resumed, no member queued twice.

mod service_support;

use contact_core::output::stored::decode_step;
use serde_json::Value;
use service_support::*;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

const ROUNDS: usize = 6;

struct Job {
    id: String,
    scene: Value,
    steps: usize,
    every: usize,
}

/// Temporary files (interrupted atomic writes) in the result directories.
fn temp_files(data: &Path) -> Vec<String> {
    let mut out = Vec::new();
    if let Ok(dirs) = std::fs::read_dir(data.join("results")) {
        for d in dirs.flatten() {
            for f in std::fs::read_dir(d.path()).into_iter().flatten().flatten() {
                let name = f.file_name().to_string_lossy().into_owned();
                if name.starts_with(".tmp-") {
                    out.push(format!("{}/{name}", d.file_name().to_string_lossy()));
                }
            }
        }
    }
    out
}

#[test]
fn kill_9_and_restart_loses_nothing() {
    let dir = TempDir::new("crash");
    let data = dir.0.join("data");
    // A job killed before its first checkpoint in `--max-attempts` rounds in a row is
    // rightly failed as abandoned (the store contract tests that); here every accepted job
    // must finish, so no job may run out of attempts however the kills fall.
    let max_attempts = (ROUNDS + 1).to_string();
    let args = [
        "--max-attempts",
        &max_attempts,
        "--workers",
        "2",
        "--submit-rate",
        "0",
        "--max-steps",
        "1000000",
    ];
    let t0 = Instant::now();
    let mut rng = Rng::seeded(0xc4a5_11ed_0000_0001);
    let mut jobs: Vec<Job> = Vec::new();
    let mut kills_running = 0;
    let mut kills_mid_write = 0;
    let mut interrupted: BTreeMap<String, usize> = BTreeMap::new();
    let mut inflight = 0;
    for round in 0..ROUNDS {
        let srv = Proc::start(&data, &args);
        let a = srv.addr;
        // A restarted server serves only complete results: every job that succeeded so far
        // has its summary.
        for j in &jobs {
            let r = get(a, &format!("/jobs/{}", j.id));
            assert_eq!(r.status, 200, "job {} lost after a crash", j.id);
            if r.json()["status"] == "succeeded" {
                let s = get(a, &format!("/jobs/{}/summary", j.id));
                assert_eq!(s.status, 200);
                assert_eq!(s.json()["steps"].as_array().unwrap().len(), j.steps);
            }
        }
        // New work: a long run (checkpoints), two runs that store every step of a finer
        // mesh (mostly result writes), and a quick one.
        let mut new = vec![
            long_scene(
                &format!("crash-long-{round}"),
                16,
                4000 + rng.below(2000),
                4,
            ),
            long_scene(&format!("crash-writes-{round}a"), 32, 150, 150),
            long_scene(&format!("crash-writes-{round}b"), 32, 100, 50),
            small_scene(&format!("crash-small-{round}")),
        ];
        if round == ROUNDS - 1 {
            new.truncate(1);
        }
        for scene in new {
            let r = post_json(a, "/jobs", &scene);
            assert_eq!(r.status, 202, "{}", r.text());
            let p = contact_core::scene::validate(&scene).unwrap();
            jobs.push(Job {
                id: r.json()["id"].as_str().unwrap().to_string(),
                every: scene["output"]["every"].as_u64().unwrap_or(1) as usize,
                steps: p.steps,
                scene,
            });
        }
        // Meanwhile a client keeps submitting: every 202 it gets must survive the kill.
        let stop = Arc::new(AtomicBool::new(false));
        let submitter = {
            let stop = stop.clone();
            std::thread::spawn(move || {
                let mut got = Vec::new();
                let mut k = 0;
                while !stop.load(Ordering::Relaxed) {
                    k += 1;
                    let scene = small_scene(&format!("crash-inflight-{round}-{k}"));
                    let r = try_post_json(a, "/jobs", &scene, Duration::from_secs(10));
                    match r {
                        Ok(r) if r.status == 202 => {
                            got.push((r.json()["id"].as_str().unwrap().to_string(), scene))
                        }
                        Ok(r) => panic!("submit: {} {}", r.status, r.text()),
                        // The server died while answering: not accepted.
                        Err(_) => break,
                    }
                    std::thread::sleep(Duration::from_millis(100));
                }
                got
            })
        };
        let running_now = || -> Vec<String> {
            get(a, "/jobs?status=running&limit=500").json()["jobs"]
                .as_array()
                .unwrap()
                .iter()
                .map(|j| j["id"].as_str().unwrap().to_string())
                .collect()
        };
        // The jobs running when the server is killed (interrupted).
        let running = if round % 2 == 1 {
            // Aim at a result write: kill as soon as a temporary file is seen.
            std::thread::sleep(Duration::from_millis(300));
            let running = running_now();
            let until = Instant::now() + Duration::from_secs(3);
            while temp_files(&data).is_empty() && Instant::now() < until {}
            running
        } else {
            std::thread::sleep(Duration::from_millis(300 + rng.below(2200) as u64));
            running_now()
        };
        srv.kill9();
        stop.store(true, Ordering::Relaxed);
        for (id, scene) in submitter.join().unwrap() {
            inflight += 1;
            jobs.push(Job {
                id,
                steps: 4,
                every: 1,
                scene,
            });
        }
        kills_running += usize::from(!running.is_empty());
        for id in running {
            *interrupted.entry(id).or_default() += 1;
        }
        let temps = temp_files(&data);
        if !temps.is_empty() {
            kills_mid_write += 1;
        }
        eprintln!(
            "crash: round {round}: killed at {:.1} s, {} temporary file(s) left by interrupted writes",
            t0.elapsed().as_secs_f64(),
            temps.len()
        );
    }

    // Final start: everything accepted must finish.
    let srv = Proc::start(&data, &args);
    let a = srv.addr;
    assert!(
        temp_files(&data).is_empty(),
        "temporary files survive a restart"
    );
    let mut finals: HashMap<String, Value> = HashMap::new();
    for j in &jobs {
        let f = wait_status(
            a,
            &j.id,
            &["succeeded", "failed", "cancelled"],
            Duration::from_secs(180),
        );
        finals.insert(j.id.clone(), f);
    }
    let total_s = t0.elapsed().as_secs_f64();
    let mut resumed = 0;
    let mut max_attempt = 0;
    for j in &jobs {
        let f = &finals[&j.id];
        assert_eq!(
            f["status"],
            "succeeded",
            "job {} (interrupted {} times): {f}",
            j.id,
            interrupted.get(&j.id).copied().unwrap_or(0)
        );
        let attempt = f["attempt"].as_u64().unwrap();
        max_attempt = max_attempt.max(attempt);
        resumed += usize::from(attempt > 1);
        // The summary is complete.
        let s = get(a, &format!("/jobs/{}/summary", j.id));
        assert_eq!(s.status, 200);
        let s = s.json();
        let steps = s["steps"].as_array().unwrap();
        assert_eq!(steps.len(), j.steps, "job {}", j.id);
        for (i, st) in steps.iter().enumerate() {
            assert_eq!(st["n"].as_u64().unwrap() as usize, i + 1, "job {}", j.id);
        }
        // Exactly the selected steps are stored, each complete (checksummed) and the step it
        // is named after; no temporary file is left.
        let dir = data.join("results").join(&j.id);
        let mut stored: Vec<usize> = Vec::new();
        for f in std::fs::read_dir(&dir).unwrap().flatten() {
            let name = f.file_name().to_string_lossy().into_owned();
            assert!(!name.starts_with(".tmp-"), "{}/{name}", j.id);
            if let Some(n) = contact_sim::jobs::parse_step_file(&name) {
                let fields = decode_step(&std::fs::read(f.path()).unwrap())
                    .unwrap_or_else(|e| panic!("{}/{name}: {e}", j.id));
                assert_eq!(fields.n, n, "{}/{name}", j.id);
                stored.push(n);
            }
        }
        stored.sort_unstable();
        let p = contact_core::scene::validate(&j.scene).unwrap();
        let expected: Vec<usize> = (1..=j.steps)
            .filter(|&n| p.output.stores(n, j.steps))
            .collect();
        assert_eq!(stored, expected, "job {} (every {})", j.id, j.every);
        // And they are served.
        let last = get(a, &format!("/jobs/{}/fields?step=last&fields=zeta", j.id));
        assert_eq!(last.status, 200);
        assert_eq!(
            last.json()["n"].as_u64().unwrap() as usize,
            *expected.last().unwrap()
        );
    }
    // The jobs interrupted most often end with the numbers of an uninterrupted run.
    let mut by_interruptions: Vec<&Job> = jobs.iter().collect();
    by_interruptions
        .sort_by_key(|j| std::cmp::Reverse(interrupted.get(&j.id).copied().unwrap_or(0)));
    for j in by_interruptions.iter().take(2) {
        let p = contact_core::scene::validate(&j.scene).unwrap();
        let straight = contact_core::run::run::<2>(p, Default::default(), |_, _| {
            std::ops::ControlFlow::Continue(())
        })
        .unwrap();
        let w_v = straight.final_.unwrap().w_v;
        let s = get(a, &format!("/jobs/{}/summary", j.id)).json();
        let got = s["final"]["w_V"].as_f64().unwrap();
        // Bit for bit: checkpoints carry the solvers' warm starts.
        assert_eq!(
            got.to_bits(),
            w_v.to_bits(),
            "job {} interrupted {} times: w_V {got} vs {w_v}",
            j.id,
            interrupted.get(&j.id).copied().unwrap_or(0)
        );
    }
    let interruptions: usize = interrupted.values().sum();
    eprintln!(
        "crash: {ROUNDS} kill -9 rounds in {total_s:.1} s ({kills_running} while jobs ran, \
         {kills_mid_write} with a result write in flight); {} jobs accepted ({inflight} of them \
         by a client submitting until the kill), {} succeeded, 0 lost; {interruptions} job interruptions, {resumed} jobs resumed after a crash \
         (max attempt {max_attempt})",
        jobs.len(),
        finals
            .values()
            .filter(|f| f["status"] == "succeeded")
            .count(),
    );
    assert!(kills_running > 0, "no kill hit a running job");
}

/// paper-convergence at h = 1/16 with Tresca friction and `n` steps to t = 1, only the last
/// step stored: a sweep member long enough to be caught running.
fn sweep_scene(n: u32) -> Value {
    let mut s = contact_core::scene::presets::get("paper-convergence").unwrap();
    s["mesh"]["h"] = serde_json::json!("1/16");
    s["time"] = serde_json::json!({"t_end": 1, "N": n});
    s["friction"] = serde_json::json!({"law": "tresca", "g": 1});
    s["solver"] = serde_json::json!({"linear": "direct"});
    s["output"] = serde_json::json!({"every": n, "fields": ["u"]});
    s
}

/// Accepted work is never lost: the server killed (SIGKILL) while a sweep's members run
/// completes the sweep after its restart, no member enqueued twice.
#[test]
fn a_sweep_survives_a_kill_while_its_members_run() {
    let dir = TempDir::new("sweep-kill");
    let data = dir.0.join("data");
    let srv = Proc::start(&data, &["--workers", "1"]);
    let a = srv.addr;
    let r = post_json(
        a,
        "/jobs",
        &serde_json::json!({"sweep": {"scene": sweep_scene(10_000), "vary": {"/friction/g": [1, 2]}}}),
    );
    assert_eq!(r.status, 202, "{}", r.text());
    let id = r.json()["id"].as_str().unwrap().to_string();
    let t0 = Instant::now();
    let view = loop {
        let j = get(a, &format!("/jobs/{id}")).json();
        if j["progress"]["step"].as_u64().unwrap_or(0) > 0 {
            break j;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(120),
            "no member ran: {j}"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    srv.kill9();
    let srv = Proc::start(&data, &["--workers", "1"]);
    let a = srv.addr;
    let done = wait_status(a, &id, &["succeeded", "failed"], Duration::from_secs(300));
    assert_eq!(done["status"], "succeeded", "{done}");
    assert_eq!(done["members"], view["members"]);
    let summary = get(a, &format!("/jobs/{id}/summary")).json();
    assert_eq!(summary["computed"], 2);
    for row in summary["rows"].as_array().unwrap() {
        let m = get(
            a,
            &format!("/jobs/{}/summary", row["job"].as_str().unwrap()),
        )
        .json();
        assert_eq!(m["steps"].as_array().unwrap().len(), 10_000);
        assert_eq!(
            row["w_V"].as_f64().unwrap().to_bits(),
            m["final"]["w_V"].as_f64().unwrap().to_bits()
        );
    }
    // The member killed mid-run was resumed by the restarted server.
    let attempts: Vec<u64> = view["members"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| {
            get(a, &format!("/jobs/{}", m.as_str().unwrap())).json()["attempt"]
                .as_u64()
                .unwrap()
        })
        .collect();
    assert!(attempts.contains(&2), "{attempts:?}");
    // Exactly the two members and the sweep exist: nothing was enqueued twice.
    let listed = get(a, "/jobs?limit=500").json();
    assert_eq!(listed["jobs"].as_array().unwrap().len(), 3, "{listed}");
    srv.terminate();
}
