//! The shared PostgreSQL job store, on a real server from Debian's packages (started by
//! the test, see `service_support::postgres`; skipped when absent unless `CI` is set).
//!
//! * `pg_store_contract`: the job store's contract (`service_support::store_contract`, the
//!   one tests/store.rs runs against SQLite), each case on a fresh database of one server.
//! * `pg_store_migrations_and_reconnection`: migrations applied once and a newer schema
//!   refused; reconnection after the server stops and starts again.
//! * `pg_store_migrates_a_version_3_database`: a database of the previous schema upgrades
//!   at connect and keeps its jobs.
//! * `three_workers_one_api`: one API-only node and three worker processes on one database:
//!   50 jobs, each finished exactly once, spread over the workers.
//! * `kill_9_worker_mid_job`: the worker running a long job is killed; another worker
//!   resumes it from its last checkpoint and the result equals an uninterrupted run's bit
//!   for bit.
//! * `database_restart_under_load`: the database is restarted twice while jobs run and are
//!   submitted; nothing is lost, nothing is run twice to completion.
//! * `uploaded_meshes_are_shared_by_the_nodes`: a mesh uploaded through one API node is seen
//!   by another and used by a job a worker node runs; deleting it is refused while the job
//!   is queued, allowed (through any node) once it has finished.

mod service_support;

use contact_core::linalg::LinearPath;
use contact_core::output::stored::decode_step;
use contact_sim::store::postgres::PgStore;
use contact_sim::store::{JobStatus, MemoryPrediction, NewJob, Store, StoreError};
use serde_json::{json, Value};
use service_support::postgres::*;
use service_support::store_contract::{self, Fixture};
use service_support::*;
use std::collections::{HashMap, HashSet};
use std::net::SocketAddr;
use std::time::{Duration, Instant};

#[test]
fn pg_store_contract() {
    let Some(pg) = Postgres::start("contract") else {
        return;
    };
    let cases = store_contract::run("PostgreSQL", |case| {
        let url = pg.create_database(case);
        Fixture {
            store: Box::new(PgStore::connect(&url).unwrap()),
            connect: Box::new(move || Box::new(PgStore::connect(&url).unwrap())),
        }
    });
    eprintln!("PostgreSQL: {cases} contract cases passed");
}

/// What only the PostgreSQL store has: versioned migrations in the database, and a
/// connection that comes back by itself after the server went away.
#[test]
fn pg_store_migrations_and_reconnection() {
    let Some(pg) = Postgres::start("migrations") else {
        return;
    };
    let store = PgStore::connect(&pg.url()).unwrap();

    // Migrations: applied once, idempotent at the next connect.
    assert_eq!(store.schema_version().unwrap(), 5);
    let again = PgStore::connect(&pg.url()).unwrap();
    assert_eq!(again.schema_version().unwrap(), 5);

    let memory = MemoryPrediction {
        linear_path: LinearPath::Multigrid,
        predicted_bytes: 5_000_000_000,
    };
    let done = store_contract::enqueued(
        &store,
        NewJob {
            memory: Some(memory),
            ..store_contract::new_job(0)
        },
    );
    assert_eq!(done.memory, Some(memory));
    assert_eq!(again.get(done.id).unwrap().unwrap().memory, Some(memory));
    assert_eq!(store.claim("w", 60.0, 3).unwrap().unwrap().id, done.id);
    store.finish(done.id, JobStatus::Succeeded, None).unwrap();

    // The server goes away: errors are "unavailable", not panics; it comes back: the same
    // store object reconnects by itself.
    pg.stop("fast");
    match store.get(done.id) {
        Err(StoreError::Unavailable(_)) => {}
        other => panic!("expected Unavailable, got {other:?}"),
    }
    pg.start_again();
    assert_eq!(
        store.get(done.id).unwrap().unwrap().status,
        JobStatus::Succeeded
    );

    // A database migrated by a newer build is refused.
    let mut raw = ::postgres::Client::connect(&pg.url(), ::postgres::NoTls).unwrap();
    raw.execute("INSERT INTO contact_sim_schema (version) VALUES (99)", &[])
        .unwrap();
    let err = PgStore::connect(&pg.url()).unwrap_err();
    assert!(err.to_string().contains("newer"), "{err}");
}

/// A database at schema version 3 (made by taking the columns of versions 4 and 5 away again)
/// upgrades at connect: its jobs read back without a memory prediction, new jobs store theirs.
#[test]
fn pg_store_migrates_a_version_3_database() {
    let Some(pg) = Postgres::start("migrate-v3") else {
        return;
    };
    let url = pg.create_database("v3");
    drop(PgStore::connect(&url).unwrap());
    let mut raw = ::postgres::Client::connect(&url, ::postgres::NoTls).unwrap();
    raw.batch_execute(
        "ALTER TABLE jobs DROP COLUMN linear_path, DROP COLUMN predicted_bytes,
                          DROP COLUMN sweep, DROP COLUMN members;
         DELETE FROM contact_sim_schema WHERE version >= 4;
         INSERT INTO jobs (id, status, scene, scene_hash, created_at, steps, owner)
             VALUES ('00000000-0000-4000-8000-000000000001', 'queued', '{\"name\": \"old\"}',
                     'h', 1.0, 9, 'alice');",
    )
    .unwrap();
    let store = PgStore::connect(&url).unwrap();
    assert_eq!(store.schema_version().unwrap(), 5);
    let old = store
        .get("00000000-0000-4000-8000-000000000001".parse().unwrap())
        .unwrap()
        .unwrap();
    assert_eq!(old.memory, None);
    assert_eq!(
        (old.scene["name"].as_str(), old.owner.as_str()),
        (Some("old"), "alice")
    );
    let memory = MemoryPrediction {
        linear_path: LinearPath::Direct,
        predicted_bytes: 42,
    };
    let new = store_contract::enqueued(
        &store,
        NewJob {
            memory: Some(memory),
            ..store_contract::new_job(1)
        },
    );
    assert_eq!(store.get(new.id).unwrap().unwrap().memory, Some(memory));
}

/// `sha-256=:<base64>:` of `bytes` (RFC 9530), computed independently of the server.
fn sha256_digest_header(bytes: &[u8]) -> String {
    use base64::Engine as _;
    use sha2::Digest as _;
    let d = sha2::Sha256::digest(bytes);
    format!(
        "sha-256=:{}:",
        base64::engine::general_purpose::STANDARD.encode(d)
    )
}

/// A job of about 0.1 s: paper-convergence at h = 1/8 over 40 steps, 4 of them stored.
fn job_scene(name: &str) -> Value {
    long_scene(name, 8, 40, 4)
}

/// A database, a result directory shared by the nodes, and an API-only node on them
/// (dropped in this order: the node, the directory, the database).
struct Cluster {
    api: Proc,
    data: std::path::PathBuf,
    url: String,
    _dir: TempDir,
    pg: Postgres,
}

impl Cluster {
    /// None (skip) without PostgreSQL, see [`Postgres::start`].
    fn start(tag: &str) -> Option<Cluster> {
        let pg = Postgres::start(tag)?;
        let url = pg.url();
        let dir = TempDir::new(&format!("pg-{tag}"));
        let data = dir.0.join("shared");
        let api = api_node(&data, &url);
        Some(Cluster {
            api,
            data,
            url,
            _dir: dir,
            pg,
        })
    }

    /// A worker process with one worker thread.
    fn worker(&self, node: &str, lease_s: &str) -> Proc {
        Proc::worker(&self.data, &node_args(&self.url, node, lease_s))
    }

    /// Starts worker nodes "a" and "b" (2 s leases) and submits `name`: several seconds of
    /// work with slipping friction (the warm starts matter for bit-for-bit resumption);
    /// returns once the job has a checkpoint a few steps in.
    fn long_job_on_two_nodes(&self, name: &str) -> LongJobOnTwoNodes {
        let nodes: HashMap<String, Proc> = ["a", "b"]
            .iter()
            .map(|n| (n.to_string(), self.worker(n, "2")))
            .collect();
        let scene = long_scene(name, 64, 1600, 8);
        let id = submit(self.api.addr, &scene, name);
        let (holder, checkpoint) = wait_for_checkpoint(self.api.addr, &id);
        LongJobOnTwoNodes {
            nodes,
            scene,
            id,
            holder,
            checkpoint,
        }
    }
}

/// See [`Cluster::long_job_on_two_nodes`].
struct LongJobOnTwoNodes {
    /// The worker processes by node name.
    nodes: HashMap<String, Proc>,
    scene: Value,
    id: String,
    /// The node computing the job when its checkpoint was seen.
    holder: String,
    /// That checkpoint's step.
    checkpoint: u64,
}

/// Waits for job `id` to succeed and checks that the node other than `holder` (of "a" and
/// "b") finished it; returns the job resource.
fn finished_by_the_other_node(addr: SocketAddr, id: &str, holder: &str) -> Value {
    let f = wait_all(addr, &[id.to_string()], Duration::from_secs(180)).remove(0);
    assert_eq!(f["status"], "succeeded", "{f}");
    let other = if holder == "a" { "b" } else { "a" };
    assert_eq!(f["worker"].as_str(), Some(format!("{other}-w0").as_str()));
    f
}

/// Runs three tiny jobs one after the other, each of which must be done within 3 s: with
/// a 30 s lease idle workers look for work only every 10 s, so that is only met when the
/// submission woke them (LISTEN/NOTIFY).
fn assert_woken_promptly(addr: SocketAddr, tag: &str) {
    for i in 0..3 {
        let t = Instant::now();
        let id = submit(
            addr,
            &job_scene(&format!("{tag}-{i}")),
            &format!("{tag}-{i}"),
        );
        let f = &wait_all(addr, &[id], Duration::from_secs(60))[0];
        let latency = t.elapsed();
        assert_eq!(f["status"], "succeeded");
        assert!(
            latency < Duration::from_secs(3),
            "{tag}: a 10 ms job took {latency:?} on an idle cluster: workers were not woken"
        );
        std::thread::sleep(Duration::from_millis(300));
    }
}

/// Waits until job `id` has a checkpoint past step 1 and returns the node computing it
/// (the part of its worker name before `-w`) and that checkpoint step.
fn wait_for_checkpoint(addr: SocketAddr, id: &str) -> (String, u64) {
    let t = Instant::now();
    loop {
        let j = get(addr, &format!("/jobs/{id}")).json();
        if let (Some(w), Some(c)) = (j["worker"].as_str(), j["last_checkpoint_step"].as_u64()) {
            if c >= 2 {
                return (w.split('-').next().unwrap().to_string(), c);
            }
        }
        assert!(
            j["status"] != "succeeded",
            "the job finished before it could be interrupted"
        );
        assert!(t.elapsed() < Duration::from_secs(60), "no checkpoint: {j}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The job's w_V at T equals an in-process run's of `scene`, bit for bit.
fn assert_w_v_of_in_process_run(addr: SocketAddr, id: &str, scene: &Value) {
    let p = contact_core::scene::validate(scene).unwrap();
    let inproc = contact_core::run::run::<2>(p, Default::default(), |_, _| {
        std::ops::ControlFlow::Continue(())
    })
    .unwrap();
    let s = get(addr, &format!("/jobs/{id}/summary")).json();
    assert_eq!(
        s["final"]["w_V"].as_f64().unwrap().to_bits(),
        inproc.final_.unwrap().w_v.to_bits()
    );
}

#[test]
fn three_workers_one_api() {
    let Some(cluster) = Cluster::start("three") else {
        return;
    };
    let api = &cluster.api;
    let workers: Vec<Proc> = (0..3)
        .map(|i| cluster.worker(&format!("w{i}"), "30"))
        .collect();
    std::thread::sleep(Duration::from_millis(500));
    assert_woken_promptly(api.addr, "probe");
    let t0 = Instant::now();
    let ids: Vec<String> = (0..50)
        .map(|i| {
            submit(
                api.addr,
                &job_scene(&format!("three-{i}")),
                &format!("three-{i}"),
            )
        })
        .collect();
    assert_eq!(ids.iter().collect::<HashSet<_>>().len(), 50);
    let finals = wait_all(api.addr, &ids, Duration::from_secs(300));
    let elapsed = t0.elapsed().as_secs_f64();
    let mut per_worker: HashMap<String, usize> = HashMap::new();
    for f in &finals {
        assert_eq!(f["status"], "succeeded", "{f}");
        assert_eq!(f["attempt"], 1, "{f}");
        *per_worker
            .entry(f["worker"].as_str().unwrap().to_string())
            .or_default() += 1;
        // Results written by a worker node are served by the API node.
        let id = f["id"].as_str().unwrap();
        let s = get(api.addr, &format!("/jobs/{id}/summary"));
        assert_eq!(s.status, 200, "{}", s.text());
        assert_eq!(
            s.header("repr-digest").map(str::to_string),
            Some(sha256_digest_header(&s.body)),
            "content hash of the summary"
        );
        assert_eq!(s.json()["steps"].as_array().unwrap().len(), 40);
        let last = get(
            api.addr,
            &format!("/jobs/{id}/fields?step=last&fields=zeta"),
        );
        assert_eq!(last.status, 200);
    }
    eprintln!("three workers: 50 jobs in {elapsed:.1} s, per worker {per_worker:?}");
    // Every job finished exactly once, by a worker node (the API node has none).
    let done = completions(&workers.iter().collect::<Vec<_>>());
    for id in &ids {
        assert_eq!(done.get(id), Some(&1), "job {id} completions");
    }
    assert_eq!(done.len(), 53);
    assert!(completions(&[api]).is_empty());
    // A job running on a worker node is cancelled through the API node (the worker sees the
    // request at its next lease renewal or checkpoint, about once a second).
    let long = submit(api.addr, &long_scene("to-cancel", 64, 4000, 2), "to-cancel");
    let t = Instant::now();
    while get(api.addr, &format!("/jobs/{long}")).json()["status"] != "running" {
        assert!(t.elapsed() < Duration::from_secs(30), "never started");
        std::thread::sleep(Duration::from_millis(50));
    }
    let c = http(api.addr, "POST", &format!("/jobs/{long}/cancel"), &[], b"");
    assert!(c.status < 300, "{}", c.text());
    let t = Instant::now();
    let f = &wait_all(
        api.addr,
        std::slice::from_ref(&long),
        Duration::from_secs(30),
    )[0];
    assert_eq!(f["status"], "cancelled", "{f}");
    assert!(
        t.elapsed() < Duration::from_secs(10),
        "cancel took {:?}",
        t.elapsed()
    );
    let health = get(api.addr, "/healthz").json();
    assert_eq!(
        (health["store"].as_str(), health["workers"].as_u64()),
        (Some("postgres"), Some(0))
    );
    // Spread: each of the three workers ran a share.
    assert_eq!(per_worker.len(), 3, "{per_worker:?}");
    for (w, n) in &per_worker {
        assert!(w.starts_with('w') && w.ends_with("-w0"), "{w}");
        assert!(
            *n >= 5,
            "worker {w} ran only {n} of 50 jobs: {per_worker:?}"
        );
    }
}

#[test]
fn kill_9_worker_mid_job() {
    let Some(cluster) = Cluster::start("kill") else {
        return;
    };
    let (api, data) = (&cluster.api, &cluster.data);
    let LongJobOnTwoNodes {
        mut nodes,
        scene,
        id,
        holder,
        checkpoint,
    } = cluster.long_job_on_two_nodes("interrupted");
    // Kill the node running the job.
    nodes.remove(&holder).unwrap().kill9();
    let survivor = nodes.values().next().unwrap();
    let f = finished_by_the_other_node(api.addr, &id, &holder);
    assert_eq!(f["attempt"], 2, "{f}");
    // Resumed from a checkpoint at or after the one seen before the kill, not from scratch.
    let log = survivor.log.lock().unwrap().clone();
    let resumed_at: u64 = log
        .lines()
        .find_map(|l| l.split(&format!("job {id} resumed from step ")).nth(1))
        .and_then(|r| r.split_whitespace().next()?.parse().ok())
        .unwrap_or_else(|| panic!("no resumption logged: {log}"));
    assert!(
        resumed_at >= checkpoint,
        "resumed at {resumed_at} < {checkpoint}"
    );
    // Bit for bit equal to an uninterrupted run: the same scene under another idempotency key
    // (no deduplication), run by the survivor alone, and an in-process run.
    let mut straight_scene = scene.clone();
    straight_scene["name"] = json!("straight");
    let straight = submit(api.addr, &straight_scene, "straight");
    // Its progress reaches a client of the API node, which does not run it: the event
    // stream follows the stored progress (checkpoints every second, read every 2 s).
    let events = sse_text(api.addr, &straight, Duration::from_millis(4500)).unwrap();
    let steps: HashSet<u64> = events
        .split("event: progress\ndata: ")
        .skip(1)
        .filter_map(|e| serde_json::from_str::<Value>(e.lines().next()?).ok()?["step"].as_u64())
        .collect();
    assert!(
        steps.len() >= 2,
        "no progress from another node's job: {events}"
    );
    let g = &wait_all(
        api.addr,
        std::slice::from_ref(&straight),
        Duration::from_secs(180),
    )[0];
    assert_eq!(
        (g["status"].as_str(), g["attempt"].as_u64()),
        (Some("succeeded"), Some(1))
    );
    let last_step = |job: &str| {
        let dir = data.join("results").join(job);
        let mut steps: Vec<usize> = std::fs::read_dir(&dir)
            .unwrap()
            .flatten()
            .filter_map(|e| contact_sim::jobs::parse_step_file(&e.file_name().to_string_lossy()))
            .collect();
        steps.sort_unstable();
        let n = *steps.last().unwrap();
        let bytes = std::fs::read(dir.join(contact_sim::jobs::step_file(n))).unwrap();
        decode_step(&bytes).unwrap()
    };
    let (x, y) = (last_step(&id), last_step(&straight));
    assert_eq!(x.n, 1600);
    let bits = |v: &Option<Vec<f64>>| -> Vec<u64> {
        v.as_ref().unwrap().iter().map(|x| x.to_bits()).collect()
    };
    assert_eq!(bits(&x.u), bits(&y.u), "u at T");
    assert_eq!(bits(&x.w), bits(&y.w), "w at T");
    assert_eq!(bits(&x.zeta), bits(&y.zeta), "ζ at T");
    assert_w_v_of_in_process_run(api.addr, &id, &scene);
    eprintln!(
        "kill -9: node {holder} killed after checkpoint {checkpoint}; worker {} resumed at \
         step {resumed_at}; final fields equal bit for bit",
        f["worker"]
    );
}

#[test]
fn database_restart_under_load() {
    let Some(cluster) = Cluster::start("restart") else {
        return;
    };
    let workers: Vec<Proc> = (0..3)
        .map(|i| cluster.worker(&format!("r{i}"), "30"))
        .collect();
    let addr = cluster.api.addr;
    let n_jobs = 36;
    // Submissions go on while the database restarts (retried with their keys).
    let submitter = std::thread::spawn(move || {
        (0..n_jobs)
            .map(|i| {
                let scene = long_scene(&format!("restart-{i}"), 16, 800, 4);
                let id = submit(addr, &scene, &format!("restart-{i}"));
                std::thread::sleep(Duration::from_millis(60));
                id
            })
            .collect::<Vec<String>>()
    });
    std::thread::sleep(Duration::from_millis(800));
    cluster.pg.restart("fast");
    std::thread::sleep(Duration::from_millis(1200));
    // A crash of the database server this time (recovery from its WAL at start).
    cluster.pg.restart("immediate");
    let ids = submitter.join().unwrap();
    assert_eq!(ids.iter().collect::<HashSet<_>>().len(), n_jobs);
    let finals = wait_all(addr, &ids, Duration::from_secs(300));
    for f in &finals {
        assert_eq!(f["status"], "succeeded", "{f}");
    }
    // No job lost or duplicated in the store…
    let listed = get_retrying(addr, "/jobs?limit=500").json();
    assert_eq!(listed["jobs"].as_array().unwrap().len(), n_jobs, "{listed}");
    // …and none run to completion twice.
    let done = completions(&workers.iter().collect::<Vec<_>>());
    for id in &ids {
        assert_eq!(done.get(id), Some(&1), "job {id} completions: {done:?}");
    }
    // The workers' notification connections came back too.
    assert_woken_promptly(addr, "after-restarts");
    let reconnects: usize = workers
        .iter()
        .map(|w| w.log.lock().unwrap().matches("unavailable").count())
        .sum();
    assert!(reconnects > 0, "the workers never saw the database go away");
    eprintln!(
        "database restarts: {n_jobs} jobs submitted across two restarts, all succeeded once; \
         {reconnects} store-unavailable retries logged by the workers"
    );
}

#[test]
fn paused_worker_loses_its_job_and_does_not_finish_it() {
    let Some(cluster) = Cluster::start("pause") else {
        return;
    };
    let api = &cluster.api;
    let LongJobOnTwoNodes {
        nodes,
        scene,
        id,
        holder,
        ..
    } = cluster.long_job_on_two_nodes("paused");
    let signal = |sig: &str| {
        let pid = nodes[&holder].pid().to_string();
        assert!(std::process::Command::new("kill")
            .args([sig, &pid])
            .status()
            .unwrap()
            .success());
    };
    // The holder hangs (SIGSTOP): its lease runs out and the other node takes the job over.
    signal("-STOP");
    let t = Instant::now();
    loop {
        let j = get(api.addr, &format!("/jobs/{id}")).json();
        if j["attempt"] == 2 {
            break;
        }
        assert!(
            t.elapsed() < Duration::from_secs(30),
            "never taken over: {j}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    // It wakes up mid-step: it must notice and stop, not finish the job a second time.
    signal("-CONT");
    finished_by_the_other_node(api.addr, &id, &holder);
    let t = Instant::now();
    let stale = &nodes[&holder];
    while !stale
        .log
        .lock()
        .unwrap()
        .contains("taken over by another worker")
    {
        assert!(
            t.elapsed() < Duration::from_secs(10),
            "the paused worker did not notice: {}",
            stale.log.lock().unwrap()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    let done = completions(&nodes.values().collect::<Vec<_>>());
    assert_eq!(done.get(&id), Some(&1), "completions {done:?}");
    // The result is the uninterrupted one.
    assert_w_v_of_in_process_run(api.addr, &id, &scene);
}

#[test]
fn a_node_started_before_the_database_waits_for_it() {
    let Some(pg) = Postgres::start("late") else {
        return;
    };
    pg.stop("fast");
    let url = pg.url();
    let dir = TempDir::new("pg-late");
    let data = dir.0.join("shared");
    let t = Instant::now();
    let worker = std::thread::scope(|s| {
        s.spawn(|| {
            std::thread::sleep(Duration::from_secs(2));
            pg.start_again();
        });
        Proc::worker(&data, &node_args(&url, "early", "30"))
    });
    assert!(t.elapsed() >= Duration::from_secs(2));
    assert!(worker
        .log
        .lock()
        .unwrap()
        .contains("waiting for the database"));
    // And it works: a job submitted through an API node runs on it.
    let api = api_node(&data, &url);
    let id = submit(api.addr, &job_scene("late"), "late");
    let f = &wait_all(api.addr, &[id], Duration::from_secs(60))[0];
    assert_eq!(
        (f["status"].as_str(), f["worker"].as_str()),
        (Some("succeeded"), Some("early-w0"))
    );
    // TLS required of a server without it: a configuration error, reported at once rather
    // than waited on.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_contact-sim"))
        .args(["worker", "--data-dir"])
        .arg(&data)
        .args(["--store", &format!("{url}?sslmode=require")])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("server does not support TLS"), "{err}");
}

/// Meshes on the shared store: uploaded through the API node (its row in the database, its
/// file in the shared directory), used by a job that a worker node runs, refused deletion
/// while that job is unfinished; a second API node sees the same meshes.
#[test]
fn uploaded_meshes_are_shared_by_the_nodes() {
    let Some(cluster) = Cluster::start("meshes") else {
        return;
    };
    let api = &cluster.api;
    let plate = std::fs::read(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("crates/contact-core/preset-meshes/plate-with-hole.msh"),
    )
    .unwrap();
    let octet = [("Content-Type", "application/octet-stream")];
    let r = http(api.addr, "POST", "/meshes", &octet, &plate);
    assert_eq!(r.status, 201, "{}", r.text());
    let mesh = r.json()["id"].as_str().unwrap().to_string();
    assert!(cluster
        .data
        .join("meshes")
        .join(format!("{mesh}.msh"))
        .is_file());
    // Another API node on the same store and directory: the same mesh, an idempotent upload.
    let other = Proc::start(
        &cluster.data,
        &["--store", &cluster.url, "--node", "api2", "--workers", "0"],
    );
    assert_eq!(
        get(other.addr, &format!("/meshes/{mesh}")).json(),
        get(api.addr, &format!("/meshes/{mesh}")).json()
    );
    assert_eq!(
        http(other.addr, "POST", "/meshes", &octet, &plate).status,
        200
    );
    assert_eq!(get(other.addr, &format!("/meshes/{mesh}/file")).body, plate);

    // A job on it, long enough to be refused deletion while it runs on the worker node.
    let mut scene = contact_core::scene::presets::get("plate-with-hole").unwrap();
    scene["domain"] = json!({"mesh": mesh});
    scene["time"] = json!({"t_end": 1, "N": 40});
    scene["output"]["every"] = json!(40);
    // Queued (no worker yet): the mesh cannot go.
    let id = submit(api.addr, &scene, "plate-on-worker");
    let r = http(other.addr, "DELETE", &format!("/meshes/{mesh}"), &[], b"");
    assert_eq!(r.status, 409, "{}", r.text());
    let _worker = cluster.worker("mw", "30");
    let f = &wait_all(
        api.addr,
        std::slice::from_ref(&id),
        Duration::from_secs(120),
    )[0];
    assert_eq!(
        (f["status"].as_str(), f["worker"].as_str()),
        (Some("succeeded"), Some("mw-w0")),
        "{f}"
    );
    let nodes = get(api.addr, &format!("/meshes/{mesh}")).json()["summary"]["nodes"].clone();
    let fields = get(other.addr, &format!("/jobs/{id}/fields?mesh=1")).json();
    assert_eq!(
        fields["mesh"]["nodes"].as_array().unwrap().len() as u64,
        nodes.as_u64().unwrap()
    );
    // Finished: the mesh may go, on any node; the others no longer find it.
    assert_eq!(
        http(other.addr, "DELETE", &format!("/meshes/{mesh}"), &[], b"").status,
        204
    );
    assert_eq!(get(api.addr, &format!("/meshes/{mesh}")).status, 404);
    let r = post_json(api.addr, "/jobs", &scene);
    assert_eq!(r.status, 422, "{}", r.text());
    assert!(!cluster
        .data
        .join("meshes")
        .join(format!("{mesh}.msh"))
        .exists());
}
