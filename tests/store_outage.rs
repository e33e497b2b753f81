//! A job store that fails during a submission (`POST /jobs`, `POST /meshes`) is answered 503
//! problem+json with `Retry-After` — not 422 (the request is not at fault) nor 500 — nothing
//! of the refused request is kept, and the node serves again once the store is back. The
//! store fails for real:
//!
//! * SQLite: another process holds the database's write lock (`BEGIN EXCLUSIVE`) past the
//!   node's busy timeout, then lets it go;
//! * PostgreSQL: the server is stopped, then started again (skipped when PostgreSQL is not
//!   installed, unless `CI` is set).

mod service_support;

use contact_core::scene::presets::bundled_mesh;
use serde_json::{json, Value};
use service_support::postgres::{node_args, Postgres};
use service_support::*;
use std::net::SocketAddr;
use std::path::Path;
use std::time::{Duration, Instant};

const OCTETS: (&str, &str) = ("Content-Type", "application/octet-stream");

/// Asserts the answer to a submission during an outage: 503, problem+json, a positive
/// `Retry-After`, a detail that says to retry.
fn assert_outage(r: &Resp, what: &str) {
    let p = assert_problem(r, 503);
    let wait: u32 = r
        .header("retry-after")
        .unwrap_or_else(|| panic!("{what}: no Retry-After: {p}"))
        .parse()
        .unwrap_or_else(|e| panic!("{what}: Retry-After: {e}"));
    assert!(wait >= 1, "{what}: Retry-After {wait}");
    let detail = p["detail"].as_str().unwrap();
    assert!(detail.contains("retry"), "{what}: {detail}");
}

/// The names in `<data>/meshes` (mesh files and temporary files alike).
fn mesh_dir(data: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(data.join("meshes"))
        .map(|d| {
            d.map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    names.sort();
    names
}

/// A short job on the uploaded mesh `id` (the plate with a hole).
fn plate_scene(id: &str) -> Value {
    let mut s = contact_core::scene::presets::get("plate-with-hole").unwrap();
    s["name"] = json!("on the uploaded plate");
    s["domain"] = json!({"mesh": id});
    s["time"] = json!({"t_end": 1, "N": 1});
    s
}

/// Uploads the plate with a hole before the outage; its id.
fn upload_plate(a: SocketAddr) -> String {
    let r = upload(a, bundled_mesh("plate-with-hole.msh").unwrap());
    assert_eq!(r.status, 201, "{}", r.text());
    r.json()["id"].as_str().unwrap().to_string()
}

/// The three submissions refused during an outage: a scene, a scene on the uploaded mesh
/// `plate` (looked up in the store before anything else), a mesh.
fn assert_submissions_refused(a: SocketAddr, plate: &str, mesh: &[u8]) {
    assert_outage(&post_json(a, "/jobs", &small_scene("during")), "POST /jobs");
    let r = post_json(a, "/jobs", &plate_scene(plate));
    assert_outage(&r, "POST /jobs on an uploaded mesh");
    assert_outage(&upload(a, mesh), "POST /meshes");
}

fn upload(a: SocketAddr, bytes: &[u8]) -> Resp {
    http(a, "POST", "/meshes", &[OCTETS], bytes)
}

/// The ids of the jobs the node lists.
fn job_ids(a: SocketAddr) -> Vec<String> {
    get(a, "/jobs?limit=500").json()["jobs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|j| j["id"].as_str().unwrap().to_string())
        .collect()
}

/// After the outage: a submission is accepted (retrying only while the node answers 503,
/// for up to 30 s: a store that reconnects on its next call) and runs to the end; `mesh` is
/// stored with its file, beside the plate uploaded before. The job's id.
fn assert_recovered(a: SocketAddr, data: &Path, plate: &str, mesh: &[u8]) -> String {
    let t = Instant::now();
    let accepted = loop {
        let r = post_json(a, "/jobs", &small_scene("after the outage"));
        if r.status != 503 || t.elapsed() > Duration::from_secs(30) {
            break r;
        }
        std::thread::sleep(Duration::from_millis(200));
    };
    assert_eq!(accepted.status, 202, "{}", accepted.text());
    let id = accepted.json()["id"].as_str().unwrap().to_string();
    wait_status(a, &id, &["succeeded"], Duration::from_secs(120));
    let r = upload(a, mesh);
    assert_eq!(r.status, 201, "{}", r.text());
    let mesh_id = r.json()["id"].as_str().unwrap().to_string();
    assert_eq!(get(a, &format!("/meshes/{mesh_id}/file")).body, mesh);
    let mut files = vec![format!("{mesh_id}.msh"), format!("{plate}.msh")];
    files.sort();
    assert_eq!(mesh_dir(data), files);
    id
}

#[test]
fn sqlite_write_lock_held_by_another_process_is_503_then_the_node_recovers() {
    let dir = TempDir::new("outage-sqlite");
    let node = Proc::start(&dir.0, &["--workers", "1", "--submit-rate", "0"]);
    let a = node.addr;
    let plate = upload_plate(a);
    let mesh = bundled_mesh("arch-on-support.msh").unwrap();
    let before = mesh_dir(&dir.0);

    let other = rusqlite::Connection::open(dir.0.join("jobs.sqlite3")).unwrap();
    other.execute_batch("BEGIN EXCLUSIVE").unwrap();
    let t = Instant::now();
    assert_submissions_refused(a, &plate, mesh);
    eprintln!(
        "three refusals while locked took {:.1} s",
        t.elapsed().as_secs_f64()
    );
    // Reads still work (WAL): the refused jobs and mesh were not stored, nor the file.
    assert_eq!(job_ids(a), Vec::<String>::new());
    assert_eq!(mesh_dir(&dir.0), before);
    other.execute_batch("ROLLBACK").unwrap();
    drop(other);

    let id = assert_recovered(a, &dir.0, &plate, mesh);
    assert_eq!(job_ids(a), vec![id]);
    node.terminate();
}

#[test]
fn postgres_stopped_is_503_then_the_nodes_recover() {
    let Some(pg) = Postgres::start("outage") else {
        return;
    };
    let url = pg.create_database("outage");
    let data = TempDir::new("outage-pg");
    let api = Proc::start(
        &data.0,
        &[
            "--store",
            &url,
            "--node",
            "api",
            "--workers",
            "0",
            "--submit-rate",
            "0",
        ],
    );
    let _worker = Proc::worker(&data.0, &node_args(&url, "w", "5"));
    let a = api.addr;
    let plate = upload_plate(a);
    let mesh = bundled_mesh("arch-on-support.msh").unwrap();
    let before = mesh_dir(&data.0);

    pg.stop("fast");
    assert_submissions_refused(a, &plate, mesh);
    assert_eq!(mesh_dir(&data.0), before);
    pg.start_again();

    let id = assert_recovered(a, &data.0, &plate, mesh);
    assert_eq!(job_ids(a), vec![id]);
    api.terminate();
}
