//! The job store's contract: what every backend of `contact_sim::store::Store` does, written
//! once and run against each (SQLite by tests/store.rs, PostgreSQL by tests/postgres.rs).
//! What only one backend has (SQLite's file and injectable clock, PostgreSQL's migrations,
//! reconnection and notifications) is tested beside that backend.
//!
//! Every case gets a fresh, empty store. Times come from the backend's own clock (the
//! database server's for PostgreSQL), so a case never waits for a lease to run out: leases
//! are either long (60 s or more: valid throughout the case) or zero (expired as soon as the
//! clock has moved on, see [`expire`]).

use contact_sim::store::owners::{KeyAdded, Quotas};
use contact_sim::store::{
    now, parse_cursor, Enqueued, JobRecord, JobStatus, MeshDeletion, NewJob, Progress, Store,
    StoreError,
};
use serde_json::json;
use std::collections::HashSet;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::time::Duration;
use uuid::Uuid;

/// A fresh, empty store of the backend under test.
pub struct Fixture {
    pub store: Box<dyn Store>,
    /// Opens another handle on the same database, as another process would.
    pub connect: Box<dyn Fn() -> Box<dyn Store>>,
}

type Case = fn(&Fixture);

/// Every case of the contract, by name.
const CASES: &[(&str, Case)] = &[
    ("enqueue_and_get", enqueue_and_get),
    ("idempotency_keys", idempotency_keys),
    ("claims_take_the_oldest_first", claims_take_the_oldest_first),
    (
        "an_expired_lease_is_claimed_again",
        an_expired_lease_is_claimed_again,
    ),
    (
        "stalled_attempts_dead_letter_the_job",
        stalled_attempts_dead_letter_the_job,
    ),
    (
        "progressing_jobs_are_never_dead_lettered",
        progressing_jobs_are_never_dead_lettered,
    ),
    ("cancel_a_running_job", cancel_a_running_job),
    (
        "a_dead_workers_cancel_requested_job_is_cancelled",
        a_dead_workers_cancel_requested_job_is_cancelled,
    ),
    (
        "a_cancelled_queued_job_is_never_claimed",
        a_cancelled_queued_job_is_never_claimed,
    ),
    ("checkpoints", checkpoints),
    ("the_first_final_status_wins", the_first_final_status_wins),
    ("list_pages_newest_first", list_pages_newest_first),
    (
        "only_finished_jobs_are_deleted",
        only_finished_jobs_are_deleted,
    ),
    ("counts_and_find_by_hash", counts_and_find_by_hash),
    (
        "release_worker_leases_by_prefix",
        release_worker_leases_by_prefix,
    ),
    ("invalid_leases_are_rejected", invalid_leases_are_rejected),
    (
        "concurrent_claims_take_each_job_once",
        concurrent_claims_take_each_job_once,
    ),
    (
        "meshes_are_added_once_and_listed_newest_first",
        meshes_are_added_once_and_listed_newest_first,
    ),
    (
        "a_mesh_is_not_deleted_under_an_unfinished_job",
        a_mesh_is_not_deleted_under_an_unfinished_job,
    ),
    (
        "concurrent_mesh_deletes_and_submissions_agree",
        concurrent_mesh_deletes_and_submissions_agree,
    ),
    (
        "keys_by_hash_revoked_and_rotated",
        keys_by_hash_revoked_and_rotated,
    ),
    ("jobs_are_scoped_by_owner", jobs_are_scoped_by_owner),
    (
        "claims_are_fair_across_owners",
        claims_are_fair_across_owners,
    ),
    ("meshes_have_owners", meshes_have_owners),
    (
        "a_requeued_job_keeps_its_checkpoint_and_attempts",
        a_requeued_job_keeps_its_checkpoint_and_attempts,
    ),
    (
        "a_sweep_waits_for_its_members",
        a_sweep_waits_for_its_members,
    ),
];

/// Runs every case on its own fixture from `fresh` (given the case's name) and fails naming
/// every case that failed (each one's panic message is printed as it happens); returns the
/// number of cases run.
pub fn run(backend: &str, fresh: impl Fn(&str) -> Fixture) -> usize {
    let mut failed = Vec::new();
    for (name, case) in CASES {
        let fixture = fresh(name);
        if catch_unwind(AssertUnwindSafe(|| case(&fixture))).is_err() {
            failed.push(*name);
        }
    }
    assert!(
        failed.is_empty(),
        "{backend}: {} of {} contract cases failed: {failed:?}",
        failed.len(),
        CASES.len()
    );
    CASES.len()
}

/// The n-th test job: a scene with nested JSON, its hash and 10 + n steps.
pub fn new_job(n: usize) -> NewJob {
    NewJob {
        scene: json!({"name": format!("scene {n}"), "n": n, "nested": {"a": [1, 2.5]}}),
        scene_hash: format!("hash{n}"),
        steps: 10 + n,
        idempotency_key: None,
        request_hash: None,
        mesh: None,
        memory: None,
    }
}

fn enqueue(store: &dyn Store, n: usize) -> JobRecord {
    enqueued(store, new_job(n))
}

/// Enqueues `job`, which must be new.
pub fn enqueued(store: &dyn Store, job: NewJob) -> JobRecord {
    match store.enqueue(job).unwrap() {
        Enqueued::New(j) => j,
        other => panic!("expected New, got {other:?}"),
    }
}

/// Lets the clock move on, past every lease given as 0 s.
fn expire() {
    std::thread::sleep(Duration::from_millis(20));
}

fn ids_of(jobs: &[JobRecord]) -> Vec<Uuid> {
    jobs.iter().map(|j| j.id).collect()
}

fn enqueue_and_get(f: &Fixture) {
    let store = &*f.store;
    let job = enqueue(store, 3);
    assert_eq!(job.status, JobStatus::Queued);
    assert_eq!(job.attempt, 0);
    assert_eq!(
        job.progress,
        Progress {
            step: 0,
            steps: 13,
            last_residual: None
        }
    );
    assert_eq!(job.scene, new_job(3).scene);
    assert_eq!(job.scene_hash, "hash3");
    assert!(job.started_at.is_none() && job.finished_at.is_none());
    assert!(!job.cancel_requested);
    assert_eq!(store.get(job.id).unwrap().unwrap(), job);
    assert!(store.get(Uuid::new_v4()).unwrap().is_none());

    let progress = Progress {
        step: 4,
        steps: 13,
        last_residual: Some(1e-9),
    };
    store.set_progress(job.id, progress).unwrap();
    assert_eq!(store.get(job.id).unwrap().unwrap().progress, progress);
    // A NaN residual is stored as none.
    store
        .set_progress(
            job.id,
            Progress {
                step: 6,
                steps: 13,
                last_residual: Some(f64::NAN),
            },
        )
        .unwrap();
    assert_eq!(
        store.get(job.id).unwrap().unwrap().progress.last_residual,
        None
    );
}

fn idempotency_keys(f: &Fixture) {
    let store = &*f.store;
    let mut a = new_job(1);
    a.idempotency_key = Some("key-1".into());
    a.request_hash = Some("rh-a".into());
    let first = match store.enqueue(a.clone()).unwrap() {
        Enqueued::New(j) => j,
        other => panic!("{other:?}"),
    };
    assert_eq!(first.idempotency_key.as_deref(), Some("key-1"));
    assert_eq!(first.request_hash.as_deref(), Some("rh-a"));
    // The same request again: that job.
    assert_eq!(
        store.enqueue(a.clone()).unwrap(),
        Enqueued::Existing(first.clone())
    );
    // The same key with another request: a conflict, naming that job.
    let mut b = new_job(2);
    b.idempotency_key = Some("key-1".into());
    b.request_hash = Some("rh-b".into());
    assert_eq!(
        store.enqueue(b).unwrap(),
        Enqueued::KeyConflict(first.clone())
    );
    // A different key is a new job.
    let mut c = a;
    c.idempotency_key = Some("key-2".into());
    assert!(matches!(store.enqueue(c).unwrap(), Enqueued::New(j) if j.id != first.id));
    assert_eq!(store.list(None, None, 10).unwrap().jobs.len(), 2);
}

fn claims_take_the_oldest_first(f: &Fixture) {
    let store = &*f.store;
    assert!(store.claim("w", 30.0, 3).unwrap().is_none());
    let ids: Vec<Uuid> = (0..3).map(|n| enqueue(store, n).id).collect();
    for (k, id) in ids.iter().enumerate() {
        let before = now();
        let job = store.claim(&format!("w{k}"), 30.0, 3).unwrap().unwrap();
        assert_eq!(job.id, *id);
        assert_eq!(job.status, JobStatus::Running);
        assert_eq!(job.attempt, 1);
        assert_eq!(job.worker.as_deref(), Some(format!("w{k}").as_str()));
        assert!(job.started_at.unwrap() >= before);
        assert!(job.lease_until.unwrap() >= before + 30.0);
    }
    assert!(store.claim("w", 30.0, 3).unwrap().is_none());
}

fn an_expired_lease_is_claimed_again(f: &Fixture) {
    let store = &*f.store;
    let id = enqueue(store, 0).id;
    let first = store.claim("a", 60.0, 3).unwrap().unwrap();
    assert_eq!((first.id, first.attempt), (id, 1));
    store.checkpoint(id, 5, b"state5").unwrap();
    // Lease still valid: nothing to claim.
    assert!(store.claim("b", 60.0, 3).unwrap().is_none());
    // Heartbeats by the owner set the lease (here: let it run out, then renew it); by
    // another worker they do not.
    assert!(store.heartbeat(id, "a", 0.0).unwrap());
    expire();
    let before = now();
    assert!(store.heartbeat(id, "a", 60.0).unwrap());
    let after = now();
    let lease = store.get(id).unwrap().unwrap().lease_until.unwrap();
    assert!(
        (before + 60.0..=after + 60.0).contains(&lease),
        "{before} {lease} {after}"
    );
    assert!(!store.heartbeat(id, "b", 60.0).unwrap());
    assert!(store.claim("b", 60.0, 3).unwrap().is_none());
    // Worker a dies; once its lease expired b takes over, keeping the first start and the
    // checkpoint.
    assert!(store.heartbeat(id, "a", 0.0).unwrap());
    expire();
    let before = now();
    let second = store.claim("b", 10.0, 3).unwrap().unwrap();
    let after = now();
    assert_eq!(second.id, id);
    assert_eq!(second.attempt, 2);
    assert_eq!(second.worker.as_deref(), Some("b"));
    assert_eq!(second.started_at, first.started_at);
    let lease = second.lease_until.unwrap();
    assert!(
        (before + 10.0..=after + 10.0).contains(&lease),
        "{before} {lease} {after}"
    );
    assert_eq!(second.last_checkpoint_step, Some(5));
    assert_eq!(
        store.load_checkpoint(id).unwrap(),
        Some((5, b"state5".to_vec()))
    );
    // The old worker has lost the job.
    assert!(!store.heartbeat(id, "a", 10.0).unwrap());
}

fn stalled_attempts_dead_letter_the_job(f: &Fixture) {
    let store = &*f.store;
    let bad = enqueue(store, 0).id;
    let good = enqueue(store, 1).id;
    for attempt in 1..=3 {
        let j = store
            .claim(&format!("w{attempt}"), 0.0, 2)
            .unwrap()
            .unwrap();
        assert_eq!((j.id, j.attempt), (bad, attempt));
        if attempt == 1 {
            // Progress in the first attempt: the second one does not count.
            store.checkpoint(bad, 1, b"x").unwrap();
        }
        expire(); // the worker dies
    }
    // bad stalled twice in a row = max_attempts: failed, and the claim moves on to good.
    let before = now();
    let j = store.claim("w", 60.0, 2).unwrap().unwrap();
    let after = now();
    assert_eq!(j.id, good);
    assert!(store.claim("w", 60.0, 2).unwrap().is_none());
    let failed = store.get(bad).unwrap().unwrap();
    assert_eq!(failed.status, JobStatus::Failed);
    let finished = failed.finished_at.unwrap();
    assert!((before..=after).contains(&finished));
    assert_eq!(failed.lease_until, None);
    assert_eq!(failed.attempt, 3);
    let err = failed.error.unwrap();
    assert_eq!(err["type"], "about:blank");
    assert_eq!(err["title"], "job abandoned");
    assert_eq!(err["status"], 500);
    assert!(err["detail"].as_str().unwrap().contains("2 times in a row"));
    assert!(store.load_checkpoint(bad).unwrap().is_none());
}

/// A job whose every attempt saves a new checkpoint before its worker dies is never
/// abandoned (the crash test: a long job was lost after 3 kills of the server), whether the
/// dead worker's lease ran out or its restarted node released it.
fn progressing_jobs_are_never_dead_lettered(f: &Fixture) {
    let store = &*f.store;
    let id = enqueue(store, 0).id;
    for attempt in 1..=10u32 {
        let j = store.claim("node-w0", 30.0, 3).unwrap().unwrap();
        assert_eq!(
            (j.id, j.attempt, j.status),
            (id, attempt, JobStatus::Running)
        );
        store
            .checkpoint(id, attempt as usize * 100, b"state")
            .unwrap();
        // kill -9, restart: the new process releases the old leases.
        assert_eq!(store.release_worker_leases("node-").unwrap(), 1);
    }
    // Three more kills without a new checkpoint: abandoned at the next claim.
    for _ in 0..3 {
        assert!(store.claim("node-w0", 30.0, 3).unwrap().is_some());
        store.release_worker_leases("node-").unwrap();
    }
    assert!(store.claim("node-w0", 30.0, 3).unwrap().is_none());
    let rec = store.get(id).unwrap().unwrap();
    assert_eq!(rec.status, JobStatus::Failed);
    assert_eq!(rec.attempt, 13);

    let p = enqueue(store, 1).id;
    for attempt in 1..=6u32 {
        let j = store.claim("w", 0.0, 2).unwrap().unwrap();
        assert_eq!((j.id, j.attempt), (p, attempt));
        store.checkpoint(p, attempt as usize, b"s").unwrap();
        expire();
    }
    store.finish(p, JobStatus::Succeeded, None).unwrap();
    assert_eq!(store.get(p).unwrap().unwrap().status, JobStatus::Succeeded);
}

fn cancel_a_running_job(f: &Fixture) {
    let store = &*f.store;
    let id = enqueue(store, 0).id;
    store.claim("w", 60.0, 3).unwrap().unwrap();
    assert!(store.heartbeat(id, "w", 60.0).unwrap());
    let rec = store.request_cancel(id).unwrap().unwrap();
    assert_eq!(rec.status, JobStatus::Running);
    assert!(rec.cancel_requested);
    // The worker sees the request at its next heartbeat.
    assert!(!store.heartbeat(id, "w", 60.0).unwrap());
    store.finish(id, JobStatus::Cancelled, None).unwrap();
    let rec = store.get(id).unwrap().unwrap();
    assert_eq!(rec.status, JobStatus::Cancelled);
    assert_eq!(rec.worker.as_deref(), Some("w"));
    assert_eq!(rec.lease_until, None);
    assert!(rec.finished_at.is_some());
    assert!(!store.heartbeat(id, "w", 60.0).unwrap());
    // Cancelling a finished job changes nothing.
    assert_eq!(store.request_cancel(id).unwrap().unwrap(), rec);
    assert!(store.request_cancel(Uuid::new_v4()).unwrap().is_none());
}

fn a_dead_workers_cancel_requested_job_is_cancelled(f: &Fixture) {
    let store = &*f.store;
    let id = enqueue(store, 0).id;
    store.claim("a", 60.0, 3).unwrap().unwrap();
    store.checkpoint(id, 2, b"ck").unwrap();
    store.request_cancel(id).unwrap();
    // The worker's last renewal (it sees the request), then it dies.
    assert!(!store.heartbeat(id, "a", 0.0).unwrap());
    expire();
    // The next claim records the job cancelled instead of running it again.
    assert!(store.claim("b", 10.0, 3).unwrap().is_none());
    let rec = store.get(id).unwrap().unwrap();
    assert_eq!(rec.status, JobStatus::Cancelled);
    assert_eq!(rec.attempt, 1);
    assert!(rec.finished_at.is_some());
    assert_eq!(rec.lease_until, None);
    assert!(store.load_checkpoint(id).unwrap().is_none());
}

fn a_cancelled_queued_job_is_never_claimed(f: &Fixture) {
    let store = &*f.store;
    let id = enqueue(store, 0).id;
    let rec = store.request_cancel(id).unwrap().unwrap();
    assert_eq!(rec.status, JobStatus::Cancelled);
    assert!(rec.finished_at.is_some());
    assert!(store.claim("w", 60.0, 3).unwrap().is_none());
    // Even with every lease released and the clock moved on.
    store.release_worker_leases("").unwrap();
    expire();
    assert!(store.claim("w", 60.0, 3).unwrap().is_none());
    assert_eq!(store.get(id).unwrap().unwrap().status, JobStatus::Cancelled);
}

fn checkpoints(f: &Fixture) {
    let store = &*f.store;
    let id = enqueue(store, 0).id;
    // Not running yet: ignored.
    store.checkpoint(id, 1, b"early").unwrap();
    assert!(store.load_checkpoint(id).unwrap().is_none());
    store.claim("w", 60.0, 3).unwrap().unwrap();
    assert!(store.load_checkpoint(id).unwrap().is_none());
    let big: Vec<u8> = (0..200_000u32).map(|i| (i % 251) as u8).collect();
    store.checkpoint(id, 3, b"three").unwrap();
    assert_eq!(
        store.load_checkpoint(id).unwrap(),
        Some((3, b"three".to_vec()))
    );
    store.checkpoint(id, 7, &big).unwrap();
    assert_eq!(store.load_checkpoint(id).unwrap(), Some((7, big)));
    let rec = store.get(id).unwrap().unwrap();
    assert_eq!(rec.last_checkpoint_step, Some(7));
    assert_eq!(rec.progress.step, 7);
    store.finish(id, JobStatus::Succeeded, None).unwrap();
    assert!(store.load_checkpoint(id).unwrap().is_none());
    let rec = store.get(id).unwrap().unwrap();
    assert_eq!(rec.status, JobStatus::Succeeded);
    assert_eq!(rec.last_checkpoint_step, None);
    // Late checkpoint after finish: ignored.
    store.checkpoint(id, 8, b"late").unwrap();
    assert!(store.load_checkpoint(id).unwrap().is_none());
    assert_eq!(store.get(id).unwrap().unwrap().last_checkpoint_step, None);
    assert!(store.load_checkpoint(Uuid::new_v4()).unwrap().is_none());
}

fn the_first_final_status_wins(f: &Fixture) {
    let store = &*f.store;
    let id = enqueue(store, 0).id;
    store.claim("w", 60.0, 3).unwrap().unwrap();
    assert!(matches!(
        store.finish(id, JobStatus::Running, None),
        Err(StoreError::Db(_))
    ));
    assert!(matches!(
        store.finish(id, JobStatus::Queued, None),
        Err(StoreError::Db(_))
    ));
    let problem = json!({"type": "about:blank", "title": "diverged", "status": 422});
    store
        .finish(id, JobStatus::Failed, Some(problem.clone()))
        .unwrap();
    store.finish(id, JobStatus::Succeeded, None).unwrap();
    let rec = store.get(id).unwrap().unwrap();
    assert_eq!(rec.status, JobStatus::Failed);
    assert_eq!(rec.error, Some(problem));
    // The other way round: a late error does not stick to a succeeded job.
    let ok = enqueue(store, 1).id;
    store.claim("w", 60.0, 3).unwrap().unwrap();
    store.finish(ok, JobStatus::Succeeded, None).unwrap();
    store
        .finish(ok, JobStatus::Failed, Some(json!({"title": "late"})))
        .unwrap();
    let done = store.get(ok).unwrap().unwrap();
    assert_eq!(
        (
            done.status,
            done.error.is_none(),
            done.lease_until,
            done.last_checkpoint_step
        ),
        (JobStatus::Succeeded, true, None, None)
    );
    assert!(!store.heartbeat(ok, "w", 60.0).unwrap());
    // Absent job: no-op.
    store
        .finish(Uuid::new_v4(), JobStatus::Succeeded, None)
        .unwrap();
}

fn list_pages_newest_first(f: &Fixture) {
    let store = &*f.store;
    let ids: Vec<Uuid> = (0..10).map(|n| enqueue(store, n).id).collect();
    // Cancel jobs 2 and 5 (queued → cancelled): 8 queued remain.
    store.request_cancel(ids[2]).unwrap();
    store.request_cancel(ids[5]).unwrap();
    let queued_newest_first: Vec<Uuid> = ids
        .iter()
        .rev()
        .copied()
        .filter(|id| *id != ids[2] && *id != ids[5])
        .collect();

    let mut seen = Vec::new();
    let mut cursor: Option<String> = None;
    let mut pages = 0;
    loop {
        let page = store
            .list(Some(JobStatus::Queued), cursor.as_deref(), 3)
            .unwrap();
        pages += 1;
        assert!(page.jobs.iter().all(|j| j.status == JobStatus::Queued));
        seen.extend(ids_of(&page.jobs));
        match page.next {
            Some(c) => {
                assert!(parse_cursor(&c).is_some());
                cursor = Some(c);
            }
            None => break,
        }
    }
    assert_eq!(pages, 3);
    assert_eq!(seen, queued_newest_first);

    let all = store.list(None, None, 100).unwrap();
    assert!(all.next.is_none());
    assert_eq!(
        ids_of(&all.jobs),
        ids.iter().rev().copied().collect::<Vec<_>>()
    );
    let cancelled = store.list(Some(JobStatus::Cancelled), None, 100).unwrap();
    assert_eq!(ids_of(&cancelled.jobs), vec![ids[5], ids[2]]);
    // Exactly `limit` jobs left: no next page.
    let p = store.list(None, None, 10).unwrap();
    assert_eq!((p.jobs.len(), p.next), (10, None));
    // limit 0 behaves as 1.
    assert_eq!(store.list(None, None, 0).unwrap().jobs.len(), 1);
    // Bad cursors: empty page.
    for bad in [
        "",
        "s",
        "sx",
        "123",
        "s-5",
        "s0",
        "s+5",
        "s99999999999999999999999",
        "garbage",
    ] {
        assert!(parse_cursor(bad).is_none(), "{bad}");
        let p = store.list(None, Some(bad), 10).unwrap();
        assert!(p.jobs.is_empty() && p.next.is_none());
    }
}

fn only_finished_jobs_are_deleted(f: &Fixture) {
    let store = &*f.store;
    let queued = enqueue(store, 0).id;
    let running = enqueue(store, 1).id;
    let done = enqueue(store, 2).id;
    store.request_cancel(done).unwrap(); // queued → cancelled
    assert_eq!(store.claim("w", 60.0, 3).unwrap().unwrap().id, queued);
    // `queued` is now running; `running` is still queued.
    assert!(!store.delete(queued).unwrap());
    assert!(!store.delete(running).unwrap());
    assert!(store.delete(done).unwrap());
    assert!(!store.delete(done).unwrap());
    assert!(store.get(done).unwrap().is_none());
    assert!(!store.delete(Uuid::new_v4()).unwrap());
    // A succeeded job too.
    store.finish(queued, JobStatus::Succeeded, None).unwrap();
    assert!(store.delete(queued).unwrap());
    assert!(!store.delete(queued).unwrap());
}

fn counts_and_find_by_hash(f: &Fixture) {
    let store = &*f.store;
    let zero: Vec<(JobStatus, usize)> = JobStatus::ALL.iter().map(|&s| (s, 0)).collect();
    assert_eq!(store.counts().unwrap(), zero);
    let same = |n| {
        let mut j = new_job(n);
        j.scene_hash = "H".into();
        match store.enqueue(j).unwrap() {
            Enqueued::New(j) => j.id,
            other => panic!("{other:?}"),
        }
    };
    let a = same(0);
    let b = same(1);
    let c = same(2);
    let _d = same(3);
    for _ in 0..3 {
        store.claim("w", 60.0, 3).unwrap().unwrap();
    }
    assert!(store.find_succeeded_by_hash("H").unwrap().is_none());
    // Finished in the order b, a, c (apart on the clock): the latest succeeded is a.
    store.finish(b, JobStatus::Succeeded, None).unwrap();
    expire();
    store.finish(a, JobStatus::Succeeded, None).unwrap();
    expire();
    store.finish(c, JobStatus::Failed, None).unwrap();
    assert_eq!(store.find_succeeded_by_hash("H").unwrap().unwrap().id, a);
    assert!(store.find_succeeded_by_hash("other").unwrap().is_none());
    assert_eq!(
        store.counts().unwrap(),
        vec![
            (JobStatus::Queued, 1),
            (JobStatus::Running, 0),
            (JobStatus::Succeeded, 2),
            (JobStatus::Failed, 1),
            (JobStatus::Cancelled, 0),
        ]
    );
}

fn release_worker_leases_by_prefix(f: &Fixture) {
    let store = &*f.store;
    let a = enqueue(store, 0).id;
    let b = enqueue(store, 1).id;
    let c = enqueue(store, 2).id;
    store.claim("node1-w0", 3600.0, 3).unwrap().unwrap();
    store.claim("node2-w0", 3600.0, 3).unwrap().unwrap();
    store.claim("node10-w0", 3600.0, 3).unwrap().unwrap();
    assert_eq!(store.release_worker_leases("node1-").unwrap(), 1);
    // The prefix is literal text, not a pattern.
    assert_eq!(store.release_worker_leases("node_").unwrap(), 0);
    assert_eq!(store.release_worker_leases("node%").unwrap(), 0);
    let j = store.claim("node1-w1", 3600.0, 3).unwrap().unwrap();
    assert_eq!((j.id, j.attempt), (a, 2));
    assert!(store.claim("node1-w1", 3600.0, 3).unwrap().is_none());
    assert_eq!(
        store.get(b).unwrap().unwrap().worker.as_deref(),
        Some("node2-w0")
    );
    assert_eq!(
        store.get(c).unwrap().unwrap().worker.as_deref(),
        Some("node10-w0")
    );
}

fn invalid_leases_are_rejected(f: &Fixture) {
    let store = &*f.store;
    enqueue(store, 0);
    assert!(store.claim("w", f64::NAN, 3).is_err());
    assert!(store.claim("w", -1.0, 3).is_err());
    assert!(store.claim("w", f64::INFINITY, 3).is_err());
    assert!(store.claim("w", 1.0, 3).unwrap().is_some());
}

/// Six workers claim 50 jobs at once, two through the fixture's handle and four through
/// connections of their own: each job is claimed (at its first attempt) and finished once.
fn concurrent_claims_take_each_job_once(f: &Fixture) {
    let jobs: HashSet<Uuid> = (0..50).map(|n| enqueue(&*f.store, n).id).collect();
    let own: Vec<Box<dyn Store>> = (0..4).map(|_| (f.connect)()).collect();
    let mut handles: Vec<&dyn Store> = vec![&*f.store, &*f.store];
    handles.extend(own.iter().map(|s| &**s));
    let claimed: Vec<Uuid> = std::thread::scope(|s| {
        let workers: Vec<_> = handles
            .into_iter()
            .enumerate()
            .map(|(w, store)| {
                s.spawn(move || {
                    let name = format!("w{w}");
                    let mut mine = Vec::new();
                    while let Some(job) = store.claim(&name, 600.0, 3).unwrap() {
                        assert_eq!(job.attempt, 1);
                        assert!(store.heartbeat(job.id, &name, 600.0).unwrap());
                        store.finish(job.id, JobStatus::Succeeded, None).unwrap();
                        mine.push(job.id);
                    }
                    mine
                })
            })
            .collect();
        workers
            .into_iter()
            .flat_map(|w| w.join().unwrap())
            .collect()
    });
    assert_eq!(claimed.len(), 50);
    assert_eq!(claimed.into_iter().collect::<HashSet<_>>(), jobs);
    assert!(f
        .store
        .counts()
        .unwrap()
        .contains(&(JobStatus::Succeeded, 50)));
}

/// A mesh id (64 hex digits) made from `n`, and a summary like the service's.
fn mesh(n: usize) -> (String, serde_json::Value) {
    (
        format!("{n:064x}"),
        json!({"dimension": 2, "nodes": 10 + n, "cells": 2 * n + 1,
               "groups": [{"name": "contact", "facets": n, "measure": 0.5}],
               "bounding_box": {"min": [0.0, 0.0], "max": [2.0, 1.0]}}),
    )
}

fn job_on_mesh(n: usize, mesh: &str) -> NewJob {
    NewJob {
        mesh: Some(mesh.to_string()),
        ..new_job(n)
    }
}

fn meshes_are_added_once_and_listed_newest_first(f: &Fixture) {
    let store = &*f.store;
    assert!(store.list_meshes(None, 10).unwrap().meshes.is_empty());
    let (id, summary) = mesh(1);
    assert_eq!(store.get_mesh(&id).unwrap(), None);
    let before = now();
    let (rec, new) = store.add_mesh(&id, 1234, &summary).unwrap();
    let after = now();
    assert!(new);
    assert_eq!((rec.id.as_str(), rec.bytes), (id.as_str(), 1234));
    assert_eq!(rec.summary, summary);
    assert!((before..=after).contains(&rec.created_at));
    assert_eq!(store.get_mesh(&id).unwrap(), Some(rec.clone()));
    // The same id again: the first record, not a second row.
    expire();
    let (again, new) = store.add_mesh(&id, 1234, &json!({"other": 1})).unwrap();
    assert!(!new);
    assert_eq!(again, rec);
    // From another handle too.
    let other = (f.connect)();
    assert_eq!(
        other.add_mesh(&id, 1234, &summary).unwrap(),
        (rec.clone(), false)
    );
    assert_eq!(
        store.list_meshes(None, 10).unwrap().meshes,
        vec![rec.clone()]
    );

    let ids: Vec<String> = (2..9)
        .map(|n| {
            let (id, summary) = mesh(n);
            assert!(store.add_mesh(&id, n as u64, &summary).unwrap().1);
            id
        })
        .collect();
    assert_eq!(store.delete_mesh(&ids[3]).unwrap(), MeshDeletion::Deleted);
    let mut expected: Vec<String> = std::iter::once(id.clone())
        .chain(ids.iter().cloned())
        .filter(|i| *i != ids[3])
        .collect();
    expected.reverse();
    let mut seen = Vec::new();
    let mut cursor: Option<String> = None;
    let mut pages = 0;
    loop {
        let page = store.list_meshes(cursor.as_deref(), 3).unwrap();
        pages += 1;
        seen.extend(page.meshes.into_iter().map(|m| m.id));
        match page.next {
            Some(c) => {
                assert!(parse_cursor(&c).is_some());
                cursor = Some(c);
            }
            None => break,
        }
    }
    assert_eq!(pages, 3);
    assert_eq!(seen, expected);
    let p = store.list_meshes(None, 7).unwrap();
    assert_eq!((p.meshes.len(), p.next), (7, None));
    assert_eq!(store.list_meshes(None, 0).unwrap().meshes.len(), 1);
    for bad in ["", "s0", "x", "s-1"] {
        let p = store.list_meshes(Some(bad), 10).unwrap();
        assert!(p.meshes.is_empty() && p.next.is_none(), "{bad}");
    }
    // Deleted: gone, and a second delete finds nothing; added again it is new.
    assert_eq!(store.get_mesh(&ids[3]).unwrap(), None);
    assert_eq!(store.delete_mesh(&ids[3]).unwrap(), MeshDeletion::Absent);
    let (back, new) = store.add_mesh(&ids[3], 5, &mesh(5).1).unwrap();
    assert!(new);
    assert_eq!(store.list_meshes(None, 1).unwrap().meshes, vec![back]);
}

fn a_mesh_is_not_deleted_under_an_unfinished_job(f: &Fixture) {
    let store = &*f.store;
    let (id, summary) = mesh(7);
    // No such mesh: nothing is enqueued.
    assert_eq!(
        store.enqueue(job_on_mesh(0, &id)).unwrap(),
        Enqueued::NoMesh(id.clone())
    );
    assert!(store.list(None, None, 10).unwrap().jobs.is_empty());
    store.add_mesh(&id, 10, &summary).unwrap();
    let (other, other_summary) = mesh(8);
    store.add_mesh(&other, 10, &other_summary).unwrap();
    let Enqueued::New(first) = store.enqueue(job_on_mesh(1, &id)).unwrap() else {
        panic!("not enqueued");
    };
    let Enqueued::New(second) = store.enqueue(job_on_mesh(2, &id)).unwrap() else {
        panic!("not enqueued");
    };
    // Queued, then running: refused, naming the oldest unfinished job.
    assert_eq!(
        store.delete_mesh(&id).unwrap(),
        MeshDeletion::InUse(Box::new(store.get(first.id).unwrap().unwrap()))
    );
    assert_eq!(store.claim("w", 60.0, 3).unwrap().unwrap().id, first.id);
    match store.delete_mesh(&id).unwrap() {
        MeshDeletion::InUse(j) => {
            assert_eq!((j.id, j.status), (first.id, JobStatus::Running))
        }
        other => panic!("{other:?}"),
    }
    store.finish(first.id, JobStatus::Succeeded, None).unwrap();
    match store.delete_mesh(&id).unwrap() {
        MeshDeletion::InUse(j) => assert_eq!(j.id, second.id),
        other => panic!("{other:?}"),
    }
    // Another mesh is free meanwhile.
    assert_eq!(store.delete_mesh(&other).unwrap(), MeshDeletion::Deleted);
    store.request_cancel(second.id).unwrap();
    // Only finished jobs are left: deleted; the finished jobs stay.
    assert_eq!(store.delete_mesh(&id).unwrap(), MeshDeletion::Deleted);
    assert_eq!(store.get_mesh(&id).unwrap(), None);
    assert_eq!(
        store.get(first.id).unwrap().unwrap().status,
        JobStatus::Succeeded
    );
    assert_eq!(
        store.enqueue(job_on_mesh(3, &id)).unwrap(),
        Enqueued::NoMesh(id.clone())
    );
}

/// Deletes of a mesh race submissions of jobs on it from other connections: whenever the
/// delete wins, no job was enqueued on the mesh before it; whenever a submission wins, the
/// mesh is still there for it.
fn concurrent_mesh_deletes_and_submissions_agree(f: &Fixture) {
    let own: Vec<Box<dyn Store>> = (0..2).map(|_| (f.connect)()).collect();
    for round in 0..10 {
        let (id, summary) = mesh(100 + round);
        f.store.add_mesh(&id, 1, &summary).unwrap();
        let (deleted, enqueued): (bool, Vec<Enqueued>) = std::thread::scope(|s| {
            let submitters: Vec<_> = own
                .iter()
                .enumerate()
                .map(|(k, store)| {
                    let id = id.clone();
                    s.spawn(move || {
                        (0..3)
                            .map(|i| {
                                store
                                    .enqueue(job_on_mesh(round * 10 + k * 3 + i, &id))
                                    .unwrap()
                            })
                            .collect::<Vec<_>>()
                    })
                })
                .collect();
            let deleted = f.store.delete_mesh(&id).unwrap() == MeshDeletion::Deleted;
            let enqueued = submitters
                .into_iter()
                .flat_map(|h| h.join().unwrap())
                .collect();
            (deleted, enqueued)
        });
        let new: Vec<&JobRecord> = enqueued
            .iter()
            .filter_map(|e| match e {
                Enqueued::New(j) => Some(j),
                Enqueued::NoMesh(m) => {
                    assert_eq!(*m, id);
                    None
                }
                other => panic!("{other:?}"),
            })
            .collect();
        if deleted {
            // No job is on it: a queued one would have blocked the delete, and later
            // submissions found no mesh.
            assert!(new.is_empty(), "round {round}: a job on a deleted mesh");
            assert_eq!(f.store.get_mesh(&id).unwrap(), None);
        } else {
            assert!(!new.is_empty());
            assert!(f.store.get_mesh(&id).unwrap().is_some());
        }
        for j in new {
            f.store.request_cancel(j.id).unwrap();
        }
    }
}

// Owners (`contact_sim::store::owners`): keys, jobs and meshes per owner, fair claims.

fn keys_by_hash_revoked_and_rotated(f: &Fixture) {
    let store = &*f.store;
    let quotas = Quotas {
        active_jobs: Some(3),
        stored_bytes: None,
        compute_s_per_day: Some(60.5),
    };
    let KeyAdded::Added(k) = store.add_key("alice", "h1", false, quotas).unwrap() else {
        panic!("not added");
    };
    assert_eq!(
        (k.name.as_str(), k.admin, k.quotas),
        ("alice", false, quotas)
    );
    assert_eq!(
        store
            .add_key("alice", "h2", true, Quotas::default())
            .unwrap(),
        KeyAdded::Exists
    );
    let (found, hash) = store.key_by_hash("h1").unwrap().unwrap();
    assert_eq!((found.name.as_str(), hash.as_str()), ("alice", "h1"));
    assert!(store.key_by_hash("h2").unwrap().is_none());
    // Another node sees the key, and its revocation.
    let other = (f.connect)();
    assert!(other.key_by_hash("h1").unwrap().is_some());
    store.touch_key("alice", 1234.5).unwrap();
    assert_eq!(other.keys().unwrap()[0].last_used_at, Some(1234.5));
    assert!(store.revoke_key("alice").unwrap());
    assert!(!store.revoke_key("alice").unwrap());
    assert!(other.key_by_hash("h1").unwrap().is_none());
    // Rotation: a revoked name gets a new key; the old token stays refused.
    let KeyAdded::Added(k) = store
        .add_key("alice", "h3", true, Quotas::default())
        .unwrap()
    else {
        panic!("not rotated");
    };
    assert!(k.admin && k.revoked_at.is_none() && k.last_used_at.is_none());
    assert!(store.key_by_hash("h1").unwrap().is_none());
    assert!(store.key_by_hash("h3").unwrap().is_some());
    assert!(store.set_quotas("alice", quotas).unwrap());
    assert!(!store.set_quotas("nobody", quotas).unwrap());
    assert_eq!(store.keys().unwrap()[0].quotas, quotas);
}

fn owned(store: &dyn Store, owner: &str, n: usize, key: Option<&str>, bytes: u64) -> Enqueued {
    let job = NewJob {
        idempotency_key: key.map(str::to_string),
        request_hash: Some("body".into()),
        ..new_job(n)
    };
    store.enqueue_for(owner, bytes, job).unwrap()
}

fn jobs_are_scoped_by_owner(f: &Fixture) {
    let store = &*f.store;
    let Enqueued::New(a1) = owned(store, "a", 1, Some("k"), 100) else {
        panic!("not new");
    };
    // The same idempotency key: another owner's is another job, the owner's own the same.
    let Enqueued::New(b1) = owned(store, "b", 1, Some("k"), 7) else {
        panic!("b's key is its own");
    };
    assert_ne!(a1.id, b1.id);
    assert_eq!(
        owned(store, "a", 1, Some("k"), 100),
        Enqueued::Existing(a1.clone())
    );
    assert_eq!(
        store.find_by_idempotency_key("a", "k").unwrap().unwrap().id,
        a1.id
    );
    assert!(store.find_by_idempotency_key("c", "k").unwrap().is_none());
    let Enqueued::New(a2) = owned(store, "a", 2, None, 50) else {
        panic!("not new");
    };
    assert_eq!(
        (a2.owner.as_str(), store.get(a2.id).unwrap().unwrap().owner),
        ("a", "a".into())
    );
    assert_eq!(
        ids_of(&store.list_for(Some("a"), None, None, 10).unwrap().jobs),
        vec![a2.id, a1.id]
    );
    assert_eq!(
        ids_of(&store.list_for(Some("b"), None, None, 10).unwrap().jobs),
        vec![b1.id]
    );
    assert_eq!(store.list(None, None, 10).unwrap().jobs.len(), 3);
    let page = store
        .list_for(Some("a"), Some(JobStatus::Queued), None, 1)
        .unwrap();
    assert_eq!(ids_of(&page.jobs), vec![a2.id]);
    let rest = store
        .list_for(Some("a"), None, page.next.as_deref(), 1)
        .unwrap();
    assert_eq!(ids_of(&rest.jobs), vec![a1.id]);
    // Usage: unfinished jobs, stored bytes, compute of a day.
    let u = store.usage("a", 7).unwrap();
    assert_eq!(
        (u.active_jobs, u.stored_bytes, u.compute_s_today),
        (2, 150, 0.0)
    );
    store.add_compute("a", 7, 1.5).unwrap();
    store.add_compute("a", 7, 2.0).unwrap();
    store.add_compute("a", 8, 100.0).unwrap();
    assert_eq!(store.usage("a", 7).unwrap().compute_s_today, 3.5);
    // The identical-scene shortcut: only the owner's own succeeded job.
    let claimed = store.claim("w", 60.0, 3).unwrap().unwrap();
    store
        .finish(claimed.id, JobStatus::Succeeded, None)
        .unwrap();
    let hash = &claimed.scene_hash;
    assert_eq!(
        store
            .find_succeeded_for(&claimed.owner, hash)
            .unwrap()
            .unwrap()
            .id,
        claimed.id
    );
    let stranger = if claimed.owner == "a" { "b" } else { "a" };
    if store.find_succeeded_for(stranger, hash).unwrap().is_some() {
        panic!("another owner's job was found by hash");
    }
    assert!(store.find_succeeded_by_hash(hash).unwrap().is_none());
    let u = store.usage(&claimed.owner, 7).unwrap();
    assert!(u.active_jobs <= 1);
}

fn claims_are_fair_across_owners(f: &Fixture) {
    let store = &*f.store;
    let flood: Vec<Uuid> = (0..5)
        .map(|n| match owned(store, "a", n, None, 0) {
            Enqueued::New(j) => j.id,
            other => panic!("{other:?}"),
        })
        .collect();
    let Enqueued::New(b) = owned(store, "b", 9, None, 0) else {
        panic!("not new");
    };
    // Nobody was served yet: the oldest job.
    let first = store.claim("w", 60.0, 3).unwrap().unwrap();
    assert_eq!(first.id, flood[0]);
    // a has one running: b's job, though younger than a's four.
    assert_eq!(store.claim("w2", 60.0, 3).unwrap().unwrap().id, b.id);
    store.finish(first.id, JobStatus::Succeeded, None).unwrap();
    store.finish(b.id, JobStatus::Succeeded, None).unwrap();
    // One worker: after a, b; after b, a again (least recently served first).
    let Enqueued::New(b2) = owned(store, "b", 10, None, 0) else {
        panic!("not new");
    };
    let next = store.claim("w", 60.0, 3).unwrap().unwrap();
    assert_eq!(next.id, flood[1], "a was served before b's last claim");
    store.finish(next.id, JobStatus::Succeeded, None).unwrap();
    assert_eq!(store.claim("w", 60.0, 3).unwrap().unwrap().id, b2.id);
}

fn meshes_have_owners(f: &Fixture) {
    let store = &*f.store;
    let (id, summary) = mesh(1);
    assert_eq!(
        store.add_mesh_owner("a", &id).unwrap(),
        None,
        "no such mesh yet"
    );
    store.add_mesh(&id, 100, &summary).unwrap();
    assert_eq!(store.add_mesh_owner("a", &id).unwrap(), Some(true));
    assert_eq!(store.add_mesh_owner("a", &id).unwrap(), Some(false));
    assert_eq!(store.add_mesh_owner("b", &id).unwrap(), Some(true));
    assert!(store.owned_mesh("c", &id).unwrap().is_none());
    let (va, vb) = (
        store.owned_mesh("a", &id).unwrap().unwrap(),
        store.owned_mesh("b", &id).unwrap().unwrap(),
    );
    assert_eq!((va.bytes, vb.summary.clone()), (100, summary.clone()));
    assert!(vb.created_at >= va.created_at);
    assert_eq!(
        store.list_owned_meshes("a", None, 10).unwrap().meshes.len(),
        1
    );
    assert!(store
        .list_owned_meshes("c", None, 10)
        .unwrap()
        .meshes
        .is_empty());
    assert_eq!(store.usage("a", 0).unwrap().stored_bytes, 100);
    // b's queued job keeps b's ownership; a's release leaves the mesh to b.
    let job = NewJob {
        mesh: Some(id.clone()),
        ..new_job(1)
    };
    let Enqueued::New(j) = store.enqueue_for("b", 0, job).unwrap() else {
        panic!("not new");
    };
    assert_eq!(
        store.release_mesh("a", &id).unwrap(),
        (MeshDeletion::Deleted, false)
    );
    assert_eq!(
        store.release_mesh("a", &id).unwrap(),
        (MeshDeletion::Absent, false)
    );
    assert!(matches!(
        store.release_mesh("b", &id).unwrap(),
        (MeshDeletion::InUse(_), false)
    ));
    assert!(store.get_mesh(&id).unwrap().is_some());
    store.request_cancel(j.id).unwrap();
    // The last owner's release removes the mesh: its file is the caller's to remove.
    assert_eq!(
        store.release_mesh("b", &id).unwrap(),
        (MeshDeletion::Deleted, true)
    );
    assert!(store.get_mesh(&id).unwrap().is_none());
}

/// A job put back in the queue (its worker found the disk full): queued again without its
/// worker, its attempt and stall not counted, its checkpoint kept for the next claim; only
/// the holding worker may requeue it; a cancel requested meanwhile cancels it instead.
fn a_requeued_job_keeps_its_checkpoint_and_attempts(f: &Fixture) {
    let store = &*f.store;
    let id = enqueue(store, 0).id;
    for round in 0..5 {
        let j = store.claim("w", 60.0, 1).unwrap().unwrap();
        assert_eq!((j.id, j.attempt), (id, 1), "round {round}");
        if round == 0 {
            store.checkpoint(id, 4, b"four").unwrap();
        }
        assert!(!store.requeue(id, "other").unwrap());
        assert!(store.requeue(id, "w").unwrap());
        let rec = store.get(id).unwrap().unwrap();
        assert_eq!((rec.status, rec.attempt), (JobStatus::Queued, 0));
        assert_eq!(rec.lease_until, None);
        assert_eq!(
            store.load_checkpoint(id).unwrap(),
            Some((4, b"four".to_vec()))
        );
        assert!(!store.requeue(id, "w").unwrap(), "not running");
    }
    // max_attempts = 1 and five requeues: never dead-lettered.
    store.claim("w", 60.0, 1).unwrap().unwrap();
    store.request_cancel(id).unwrap();
    assert!(store.requeue(id, "w").unwrap());
    let rec = store.get(id).unwrap().unwrap();
    assert_eq!(rec.status, JobStatus::Cancelled);
    assert!(rec.finished_at.is_some());
    assert!(store.claim("w", 60.0, 1).unwrap().is_none());
}

/// A sweep requeued with members queued or running is not claimed until they have ended, or
/// until one of them failed; its members name it, and it lists them.
fn a_sweep_waits_for_its_members(f: &Fixture) {
    let store = &*f.store;
    let sweep = enqueue(store, 1);
    let claimed = store.claim("w", 60.0, 3).unwrap().unwrap();
    assert_eq!(claimed.id, sweep.id);
    let member = |n: usize| match store.enqueue_in("", 0, new_job(n), Some(sweep.id)).unwrap() {
        Enqueued::New(j) => j,
        other => panic!("expected New, got {other:?}"),
    };
    let (a, b) = (member(2), member(3));
    assert_eq!(a.sweep, Some(sweep.id));
    assert_eq!(
        ids_of(&store.sweep_members(sweep.id).unwrap()),
        vec![a.id, b.id]
    );
    assert!(store.sweep_members(a.id).unwrap().is_empty());
    store.set_members(sweep.id, &[a.id, b.id, a.id]).unwrap();
    assert!(store.requeue(sweep.id, "w").unwrap());
    let back = store.get(sweep.id).unwrap().unwrap();
    assert_eq!(back.status, JobStatus::Queued);
    assert_eq!(back.members, vec![a.id, b.id, a.id]);
    assert_eq!(back.attempt, claimed.attempt - 1);
    // The members are claimed, oldest first; the sweep not while one of them is unfinished.
    assert_eq!(store.claim("w", 60.0, 3).unwrap().unwrap().id, a.id);
    assert_eq!(store.claim("w", 60.0, 3).unwrap().unwrap().id, b.id);
    assert!(store.claim("w", 60.0, 3).unwrap().is_none());
    store.finish(a.id, JobStatus::Succeeded, None).unwrap();
    assert!(store.claim("w", 60.0, 3).unwrap().is_none());
    store.finish(b.id, JobStatus::Succeeded, None).unwrap();
    assert_eq!(store.claim("w", 60.0, 3).unwrap().unwrap().id, sweep.id);
    // A failed member makes its sweep claimable while others still run.
    let other = enqueue(store, 4);
    assert_eq!(store.claim("w", 60.0, 3).unwrap().unwrap().id, other.id);
    let (c, d) = (
        match store.enqueue_in("", 0, new_job(5), Some(other.id)).unwrap() {
            Enqueued::New(j) => j,
            e => panic!("{e:?}"),
        },
        match store.enqueue_in("", 0, new_job(6), Some(other.id)).unwrap() {
            Enqueued::New(j) => j,
            e => panic!("{e:?}"),
        },
    );
    assert!(store.requeue(other.id, "w").unwrap());
    assert_eq!(store.claim("w", 60.0, 3).unwrap().unwrap().id, c.id);
    assert_eq!(store.claim("w", 60.0, 3).unwrap().unwrap().id, d.id);
    store
        .finish(
            c.id,
            JobStatus::Failed,
            Some(serde_json::json!({"title": "x"})),
        )
        .unwrap();
    assert_eq!(store.claim("w", 60.0, 3).unwrap().unwrap().id, other.id);
}
