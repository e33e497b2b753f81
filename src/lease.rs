//! Lease keeping independent of the numerics: while a worker runs a job, a small thread
//! renews the job's lease every third of its length, whatever the worker is doing.
//!
//! Before, the lease was renewed only at checkpoints, i.e. after a time step had finished.
//! A set-up (factorisation, Schur complement) or a single step longer than the lease —
//! reachable within the default limits: a 160,000-node mesh took 110 s for set-up and one
//! step on the shared 2-core machine — let the lease expire while the worker was still
//! computing, and an idle worker of the same process claimed the job again: the same job
//! ran twice at once, and with four workers four times, the last claim dead-lettering it
//! as "abandoned" while it was still being computed. The lease now means "the process
//! holding it is alive"; it runs out only when that process dies (crash, kill -9), which
//! is what it is for. A restarted server releases its own previous leases at once
//! (`state::start`).

use super::store::Store;
use std::sync::mpsc;
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;
use uuid::Uuid;

/// Renews the lease of one job until dropped.
pub struct Keeper {
    stop: Option<mpsc::Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

impl Keeper {
    /// Starts renewing `id`'s lease for `worker` to now + `lease_s` every `lease_s / 3`.
    pub fn start(store: Arc<dyn Store>, id: Uuid, worker: &str, lease_s: f64) -> Keeper {
        let (tx, rx) = mpsc::channel::<()>();
        let worker = worker.to_string();
        let every = Duration::from_secs_f64((lease_s / 3.0).max(0.01));
        // The job's span (see `jobs`), so that renewal failures are logged as the job's.
        let span = tracing::Span::current();
        let thread = std::thread::Builder::new()
            .name(format!("{worker}-lease"))
            .spawn(move || {
                let _entered = span.enter();
                // Until the sender is dropped (or sends).
                while let Err(mpsc::RecvTimeoutError::Timeout) = rx.recv_timeout(every) {
                    // false: cancelled, finished or not this worker's any more; the worker
                    // notices at its next checkpoint. Errors are retried at the next tick.
                    if let Err(e) = store.heartbeat(id, &worker, lease_s) {
                        tracing::warn!("lease renewal of {id} failed: {e}");
                    }
                }
            })
            .ok();
        Keeper {
            stop: Some(tx),
            thread,
        }
    }
}

impl Drop for Keeper {
    fn drop(&mut self) {
        drop(self.stop.take());
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::sqlite::SqliteStore;
    use crate::store::{Enqueued, NewJob};

    #[test]
    fn a_kept_lease_does_not_expire_however_long_the_work_takes() {
        let store: Arc<dyn Store> = Arc::new(SqliteStore::open_in_memory().unwrap());
        let Enqueued::New(job) = store
            .enqueue(NewJob {
                scene: serde_json::json!({}),
                scene_hash: "h".into(),
                steps: 1,
                idempotency_key: None,
                request_hash: None,
                mesh: None,
                memory: None,
            })
            .unwrap()
        else {
            panic!()
        };
        let lease = 0.6;
        assert_eq!(store.claim("a", lease, 3).unwrap().unwrap().id, job.id);
        let keeper = Keeper::start(store.clone(), job.id, "a", lease);
        // A "step" three leases long: nobody else may claim the job meanwhile.
        for _ in 0..6 {
            std::thread::sleep(Duration::from_secs_f64(lease / 2.0));
            assert!(store.claim("b", lease, 3).unwrap().is_none());
        }
        // The process dies (the keeper stops): the lease runs out and the job is claimable.
        drop(keeper);
        std::thread::sleep(Duration::from_secs_f64(lease * 1.5));
        let j = store.claim("b", lease, 3).unwrap().unwrap();
        assert_eq!((j.id, j.attempt), (job.id, 2));
    }
}
