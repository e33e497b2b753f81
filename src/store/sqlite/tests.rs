//! Unit tests of what only the SQLite store has: its file (WAL, reopening, migrations, the
//! `seq` counter, corrupt rows) and its injectable clock (the `*_at` methods), which pins
//! the times of leases, starts and ends exactly. The behaviour every backend shares is the
//! Store contract, tests/service_support/store_contract.rs (run by tests/store.rs).

use super::*;
use crate::store::MemoryPrediction;
use contact_core::linalg::LinearPath;
use std::path::PathBuf;

/// A directory under the system temp dir, removed on drop.
struct TempDir(PathBuf);

impl TempDir {
    fn new() -> TempDir {
        let p = std::env::temp_dir().join(format!("contact-sim-store-{}", Uuid::new_v4()));
        std::fs::create_dir_all(&p).unwrap();
        TempDir(p)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn new_job(n: usize) -> NewJob {
    NewJob {
        scene: serde_json::json!({"name": format!("scene {n}"), "n": n, "nested": {"a": [1, 2.5]}}),
        scene_hash: format!("hash{n}"),
        steps: 10 + n,
        idempotency_key: None,
        request_hash: None,
        mesh: None,
        memory: None,
    }
}

fn enqueue(store: &SqliteStore, n: usize) -> JobRecord {
    enqueued(store, new_job(n))
}

/// Enqueues `job`, which must be new.
fn enqueued(store: &SqliteStore, job: NewJob) -> JobRecord {
    match store.enqueue(job).unwrap() {
        Enqueued::New(j) => j,
        other => panic!("expected New, got {other:?}"),
    }
}

#[test]
fn expired_lease_is_reclaimed_with_next_attempt() {
    let store = SqliteStore::open_in_memory().unwrap();
    let id = enqueue(&store, 0).id;
    let t0 = 1000.0;
    let first = store.claim_at("a", 10.0, 3, t0).unwrap().unwrap();
    assert_eq!((first.id, first.attempt), (id, 1));
    store.checkpoint(id, 5, b"state5").unwrap();
    // Lease still valid: nothing to claim.
    assert!(store.claim_at("b", 10.0, 3, t0 + 5.0).unwrap().is_none());
    // Heartbeat by the owner extends; by another worker does not.
    assert!(store.heartbeat_at(id, "a", 10.0, t0 + 5.0).unwrap());
    assert!(!store.heartbeat_at(id, "b", 10.0, t0 + 5.0).unwrap());
    assert!(store.claim_at("b", 10.0, 3, t0 + 12.0).unwrap().is_none());
    // Worker a dies; after expiry b takes over, keeping the first start and checkpoint.
    let second = store.claim_at("b", 10.0, 3, t0 + 16.0).unwrap().unwrap();
    assert_eq!(second.id, id);
    assert_eq!(second.attempt, 2);
    assert_eq!(second.worker.as_deref(), Some("b"));
    assert_eq!(second.started_at, Some(t0));
    assert_eq!(second.lease_until, Some(t0 + 26.0));
    assert_eq!(second.last_checkpoint_step, Some(5));
    assert_eq!(
        store.load_checkpoint(id).unwrap(),
        Some((5, b"state5".to_vec()))
    );
    // The old worker has lost the job.
    assert!(!store.heartbeat_at(id, "a", 10.0, t0 + 17.0).unwrap());
}

/// Dead letters and cancellations found by a claim are stamped with the claim's clock, and a
/// cancelled job stays unclaimable however late the claim.
#[test]
fn claims_stamp_the_given_clock() {
    let store = SqliteStore::open_in_memory().unwrap();
    let bad = enqueue(&store, 0).id;
    let good = enqueue(&store, 1).id;
    let mut t = 1000.0;
    for attempt in 1..=2 {
        let j = store.claim_at("w", 1.0, 2, t).unwrap().unwrap();
        assert_eq!((j.id, j.attempt), (bad, attempt));
        t += 10.0; // the worker dies
    }
    assert_eq!(store.claim_at("w", 1.0, 2, t).unwrap().unwrap().id, good);
    let failed = store.get(bad).unwrap().unwrap();
    assert_eq!(failed.status, JobStatus::Failed);
    assert_eq!(failed.finished_at, Some(t));

    let id = enqueue(&store, 2).id;
    store
        .finish_at(good, JobStatus::Succeeded, None, t)
        .unwrap();
    store.claim_at("a", 10.0, 3, 2000.0).unwrap().unwrap();
    store.request_cancel_at(id, 2001.0).unwrap();
    assert!(store.claim_at("b", 10.0, 3, 2020.0).unwrap().is_none());
    let rec = store.get(id).unwrap().unwrap();
    assert_eq!(rec.status, JobStatus::Cancelled);
    assert_eq!(rec.attempt, 1);
    assert_eq!(rec.finished_at, Some(2020.0));

    let queued = enqueue(&store, 3).id;
    assert_eq!(
        store
            .request_cancel_at(queued, 3000.0)
            .unwrap()
            .unwrap()
            .finished_at,
        Some(3000.0)
    );
    store.release_worker_leases("").unwrap();
    assert!(store.claim_at("w", 60.0, 3, 1e12).unwrap().is_none());
    assert_eq!(
        store.get(queued).unwrap().unwrap().status,
        JobStatus::Cancelled
    );
}

#[test]
fn persistence_across_reopen() {
    let dir = TempDir::new();
    let path = dir.0.join("sub").join("jobs.sqlite");
    let (id, done, expected) = {
        let store = SqliteStore::open(&path).unwrap();
        let id = enqueue(&store, 0).id;
        let done = enqueue(&store, 1).id;
        store.claim("w", 60.0, 3).unwrap();
        store.checkpoint(id, 2, b"ck").unwrap();
        store.claim("w", 60.0, 3).unwrap();
        store.finish(done, JobStatus::Succeeded, None).unwrap();
        (id, done, store.get(id).unwrap().unwrap())
    };
    let store = SqliteStore::open(&path).unwrap();
    assert_eq!(store.get(id).unwrap().unwrap(), expected);
    assert_eq!(
        store.load_checkpoint(id).unwrap(),
        Some((2, b"ck".to_vec()))
    );
    assert_eq!(
        store.get(done).unwrap().unwrap().status,
        JobStatus::Succeeded
    );
    // seq keeps increasing after reopen: the new job lists first.
    let newer = enqueue(&store, 2).id;
    assert_eq!(store.list(None, None, 1).unwrap().jobs[0].id, newer);
    let mode: String = store
        .lock()
        .query_row("PRAGMA journal_mode", [], |r| r.get(0))
        .unwrap();
    assert_eq!(mode, "wal");
}

#[test]
fn seq_not_reused_after_delete() {
    let store = SqliteStore::open_in_memory().unwrap();
    let a = enqueue(&store, 0).id;
    store.request_cancel(a).unwrap();
    let cursor_before = store.list(None, None, 1).unwrap().jobs[0].id;
    assert_eq!(cursor_before, a);
    assert!(store.delete(a).unwrap());
    let b = enqueue(&store, 1).id;
    let seq: i64 = store
        .lock()
        .query_row(
            "SELECT seq FROM jobs WHERE id = ?1",
            params![b.to_string()],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!(seq, 2);
}

#[test]
fn newer_schema_is_refused() {
    let dir = TempDir::new();
    let path = dir.0.join("jobs.sqlite");
    drop(SqliteStore::open(&path).unwrap());
    {
        let conn = Connection::open(&path).unwrap();
        conn.pragma_update(None, "user_version", 99).unwrap();
    }
    assert!(matches!(
        SqliteStore::open(&path),
        Err(StoreError::Corrupt(_))
    ));
}

/// A simulation's memory prediction reads back as enqueued, across a reopen, and keeps the
/// checkpoint blob readable.
#[test]
fn memory_prediction_round_trips() {
    let dir = TempDir::new();
    let path = dir.0.join("jobs.sqlite");
    let memory = MemoryPrediction {
        linear_path: LinearPath::Multigrid,
        predicted_bytes: 5_000_000_000,
    };
    let id = {
        let store = SqliteStore::open(&path).unwrap();
        let job = enqueued(
            &store,
            NewJob {
                memory: Some(memory),
                ..new_job(0)
            },
        );
        assert_eq!(job.memory, Some(memory));
        assert_eq!(enqueue(&store, 1).memory, None);
        store.claim("w", 60.0, 3).unwrap();
        store.checkpoint(job.id, 3, b"state").unwrap();
        job.id
    };
    let store = SqliteStore::open(&path).unwrap();
    assert_eq!(store.get(id).unwrap().unwrap().memory, Some(memory));
    let listed = store.list(None, None, 10).unwrap().jobs;
    let memories: Vec<_> = listed.iter().map(|j| j.memory).collect();
    assert_eq!(memories, [None, Some(memory)]);
    assert_eq!(
        store.load_checkpoint(id).unwrap(),
        Some((3, b"state".to_vec()))
    );
}

/// A database at the previous schema version (4) upgrades on open: its jobs keep every
/// field and their checkpoints, and read back without a memory prediction; new jobs store
/// theirs.
#[test]
fn version_4_database_migrates() {
    let dir = TempDir::new();
    let path = dir.0.join("jobs.sqlite");
    let id = Uuid::new_v4();
    {
        let conn = Connection::open(&path).unwrap();
        for sql in &MIGRATIONS[..4] {
            conn.execute_batch(sql).unwrap();
        }
        conn.pragma_update(None, "user_version", 4).unwrap();
        conn.execute(
            "INSERT INTO jobs (id, seq, status, scene, scene_hash, owner, created_at, started_at,
                               step, steps, attempt, worker, lease_until, checkpoint_step,
                               stored_bytes, checkpoint)
             VALUES (?1, 7, 'running', '{\"name\": \"old\"}', 'h', 'alice', 10.0, 11.0,
                     2, 9, 1, 'n-w0', 99.0, 2, 123, x'0102')",
            params![id.to_string()],
        )
        .unwrap();
    }
    let store = SqliteStore::open(&path).unwrap();
    let version: i64 = store
        .lock()
        .pragma_query_value(None, "user_version", |r| r.get(0))
        .unwrap();
    assert_eq!(version, i64::try_from(MIGRATIONS.len()).unwrap());
    let old = store.get(id).unwrap().unwrap();
    assert_eq!(old.memory, None);
    assert_eq!(old.scene["name"], "old");
    assert_eq!(
        (old.status, old.owner.as_str()),
        (JobStatus::Running, "alice")
    );
    assert_eq!((old.progress.step, old.progress.steps), (2, 9));
    assert_eq!(old.worker.as_deref(), Some("n-w0"));
    assert_eq!(old.last_checkpoint_step, Some(2));
    assert_eq!(store.load_checkpoint(id).unwrap(), Some((2, vec![1, 2])));
    let memory = MemoryPrediction {
        linear_path: LinearPath::Direct,
        predicted_bytes: 42,
    };
    let new = enqueued(
        &store,
        NewJob {
            memory: Some(memory),
            ..new_job(1)
        },
    );
    assert_eq!(store.get(new.id).unwrap().unwrap().memory, Some(memory));
}

#[test]
fn corrupt_rows_are_errors_not_panics() {
    let store = SqliteStore::open_in_memory().unwrap();
    let id = enqueue(&store, 0).id;
    store
        .lock()
        .execute("UPDATE jobs SET scene = 'not json', step = -1", [])
        .unwrap();
    assert!(matches!(store.get(id), Err(StoreError::Corrupt(_))));
    assert!(store.list(None, None, 10).is_err());
}
