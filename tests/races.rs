//! Requests that meet at the same instant leave nothing inconsistent:
//!
//! * an upload and a delete of the same mesh through two nodes sharing one store and one
//!   data directory (two `serve` processes on one SQLite database; two API nodes on one
//!   PostgreSQL database, skipped when PostgreSQL is not installed unless `CI` is set):
//!   after every round, the mesh has a record exactly when it has its file, and the file
//!   served is the mesh's bytes;
//! * a DELETE right after the cancel of a job that is mid-run waits for the job to stop and
//!   succeeds, instead of 409.

mod service_support;

use contact_core::scene::presets::bundled_mesh;
use service_support::postgres::Postgres;
use service_support::*;
use std::net::SocketAddr;
use std::path::Path;
use std::sync::Barrier;
use std::time::{Duration, Instant};

const OCTETS: (&str, &str) = ("Content-Type", "application/octet-stream");

/// `rounds` rounds, each two uploads and two deletes of one mesh at the same instant, one of
/// each through each node (the deletes started after a random delay of up to 4 ms, so that
/// they land anywhere in the uploads' work); after each round the record and the file must
/// agree. Returns the rounds where they did not, and how.
fn hammer(nodes: [SocketAddr; 2], data: &Path, mesh: &[u8], rounds: usize) -> Vec<String> {
    let r = http(nodes[0], "POST", "/meshes", &[OCTETS], mesh);
    assert_eq!(r.status, 201, "{}", r.text());
    let id = r.json()["id"].as_str().unwrap().to_string();
    let file = data.join("meshes").join(format!("{id}.msh"));
    let mut rng = Rng::seeded(24);
    let mut broken = Vec::new();
    let (mut uploaded, mut deleted) = (0, 0);
    for round in 0..rounds {
        let delays = [rng.below(4000), rng.below(4000)].map(|us| Duration::from_micros(us as u64));
        let barrier = Barrier::new(4);
        let answers: Vec<(&str, Resp)> = std::thread::scope(|s| {
            let ops = [(0, "POST"), (1, "DELETE"), (1, "POST"), (0, "DELETE")];
            let handles: Vec<_> = ops
                .iter()
                .enumerate()
                .map(|(k, &(node, method))| {
                    let (barrier, id) = (&barrier, &id);
                    s.spawn(move || {
                        barrier.wait();
                        let r = if method == "POST" {
                            http(nodes[node], "POST", "/meshes", &[OCTETS], mesh)
                        } else {
                            std::thread::sleep(delays[k / 2]);
                            http(nodes[node], "DELETE", &format!("/meshes/{id}"), &[], b"")
                        };
                        (method, r)
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        });
        for (method, r) in &answers {
            let allowed: &[u16] = if *method == "POST" {
                &[200, 201]
            } else {
                &[204, 404]
            };
            assert!(
                allowed.contains(&r.status),
                "round {round}: {method} answered {}: {}",
                r.status,
                r.text()
            );
            uploaded += usize::from(r.status == 201);
            deleted += usize::from(r.status == 204);
        }
        let record = get(nodes[round % 2], &format!("/meshes/{id}")).status;
        assert!(record == 200 || record == 404, "round {round}: {record}");
        let on_disk = file.is_file();
        if (record == 200) != on_disk {
            broken.push(format!(
                "round {round}: GET /meshes/{{id}} {record}, file on disk: {on_disk}"
            ));
        } else if record == 200 {
            let served = get(nodes[1 - round % 2], &format!("/meshes/{id}/file"));
            assert_eq!(served.status, 200, "round {round}: {}", served.text());
            assert!(served.body == mesh, "round {round}: another file served");
        }
    }
    eprintln!(
        "{rounds} rounds: {uploaded} new uploads, {deleted} deletions, {} inconsistent",
        broken.len()
    );
    // Both kinds of outcome happened, else the rounds did not race anything.
    assert!(uploaded > rounds / 10 && deleted > rounds / 10);
    // Nothing left half-written: only the mesh's own file, if it has a record.
    let names: Vec<String> = std::fs::read_dir(data.join("meshes"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(
        names.iter().all(|n| *n == format!("{id}.msh")),
        "stray files: {names:?}"
    );
    broken
}

/// Rounds per backend. Before the record and the file changed in one store transaction,
/// about 1 round in 360 on PostgreSQL left a record without its file (5 in 1,800), so 1,000
/// rounds found it 19 times in 20; SQLite's busy handler, which makes the waiting upload
/// sleep past the racing delete, hid it (0 in 4,500).
const ROUNDS: usize = 1000;

#[test]
fn upload_and_delete_of_one_mesh_on_two_sqlite_nodes() {
    let dir = TempDir::new("race-sqlite");
    let node = |name: &str| {
        Proc::start(
            &dir.0,
            &["--node", name, "--workers", "0", "--submit-rate", "0"],
        )
    };
    let (a, b) = (node("a"), node("b"));
    let mesh = bundled_mesh("plate-with-hole.msh").unwrap();
    let broken = hammer([a.addr, b.addr], &dir.0, mesh, ROUNDS);
    assert!(broken.is_empty(), "record and file disagree: {broken:?}");
}

#[test]
fn upload_and_delete_of_one_mesh_on_two_postgres_nodes() {
    let Some(pg) = Postgres::start("meshrace") else {
        return;
    };
    let url = pg.create_database("meshrace");
    let data = TempDir::new("race-pg");
    let node = |name: &str| {
        Proc::start(
            &data.0,
            &[
                "--store",
                &url,
                "--node",
                name,
                "--workers",
                "0",
                "--submit-rate",
                "0",
            ],
        )
    };
    let (a, b) = (node("a"), node("b"));
    let mesh = bundled_mesh("plate-with-hole.msh").unwrap();
    let broken = hammer([a.addr, b.addr], &data.0, mesh, ROUNDS);
    assert!(broken.is_empty(), "record and file disagree: {broken:?}");
}

/// Waits until the job is running past its first step; its record.
fn wait_mid_run(a: SocketAddr, id: &str) -> serde_json::Value {
    let t = Instant::now();
    loop {
        let j = get(a, &format!("/jobs/{id}")).json();
        if j["status"] == "running" && j["progress"]["step"].as_u64().unwrap_or(0) >= 1 {
            return j;
        }
        assert!(
            t.elapsed() < Duration::from_secs(120),
            "job {id} never ran: {j}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn delete_right_after_cancel_waits_for_the_job_to_stop() {
    let dir = TempDir::new("cancel-delete");
    let node = Proc::start(&dir.0, &["--workers", "1", "--submit-rate", "0"]);
    let a = node.addr;
    // A job whose step happens to end between the cancel and the next request proves
    // nothing about waiting: another job then, up to three.
    let proved = (0..3).any(|attempt| cancel_then_delete(a, &dir.0, attempt));
    assert!(
        proved,
        "three jobs stopped before a request right after their cancel"
    );
    node.terminate();
}

/// Runs a long job to its first steps, then: DELETE is 409 at once (not cancelled); cancel;
/// a DELETE that will not wait is 409 "still" with Retry-After if the job is still in its
/// step (else false: nothing shown); a DELETE that waits is 204 and the job and its results
/// are gone.
fn cancel_then_delete(a: SocketAddr, data: &Path, attempt: usize) -> bool {
    let r = post_json(
        a,
        "/jobs",
        &long_scene(&format!("long steps {attempt}"), STEP_N, 100, 100),
    );
    assert_eq!(r.status, 202, "{}", r.text());
    let id = r.json()["id"].as_str().unwrap().to_string();
    let path = format!("/jobs/{id}");
    let running = wait_mid_run(a, &id);
    let results = data.join("results").join(&id);
    assert!(results.is_dir());

    // Running and not cancelled: 409 at once, saying what to do.
    let t = Instant::now();
    let p = assert_problem(&http(a, "DELETE", &path, &[], b""), 409);
    assert!(t.elapsed() < Duration::from_secs(2));
    assert!(
        p["detail"].as_str().unwrap().contains("cancel it first"),
        "{p}"
    );

    let r = http(a, "POST", &format!("{path}/cancel"), &[], b"");
    assert_eq!(r.status, 202, "{}", r.text());
    let r = http(a, "DELETE", &path, &[("Prefer", "wait=0")], b"");
    let still = r.status == 409;
    if still {
        let p = assert_problem(&r, 409);
        assert!(r.header("retry-after").is_some(), "{p}");
        assert!(p["detail"].as_str().unwrap().contains("still"), "{p}");
        // Without the preference the DELETE waits for the step to end, then deletes.
        let t = Instant::now();
        let r = http(a, "DELETE", &path, &[], b"");
        assert_eq!(r.status, 204, "{}", r.text());
        eprintln!(
            "DELETE after the cancel at step {} waited {:.2} s",
            running["progress"]["step"],
            t.elapsed().as_secs_f64()
        );
    } else {
        assert_eq!(r.status, 204, "{}", r.text());
    }
    assert_problem(&get(a, &path), 404);
    assert!(!results.exists());
    still
}

/// Mesh size of [`cancel_then_delete`]'s job: h = 1/STEP_N, whose time steps take about
/// half a second in a test build, so that a request made right after the cancel meets the
/// job in its step.
const STEP_N: usize = 256;
