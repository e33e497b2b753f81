//! Job execution: a fixed pool of worker threads (never the async runtime's threads) claims
//! jobs from the store, runs the time loop, writes stored steps and the summary atomically,
//! checkpoints (u, ζ, step) about once a second, checks cancellation every step, and
//! publishes progress to live subscribers (SSE).
//!
//! Restart safety: a job's state is (u, ζ, step) plus the per-step reports so far; a worker
//! that dies leaves the job `running` with an expiring lease, and the next claim resumes it
//! from the last checkpoint.

use super::meshes::Meshes;
use super::problem::Problem;
use super::store::results::ResultFiles;
use super::store::{JobRecord, JobStatus, Progress, Store, StoreError};
use super::Config;
use axum::http::StatusCode;
use contact_core::scene::{self, canonical, hex_sha256};
use contact_core::solve::{SolveError, SolverSettings};
use contact_core::study::{self, ReferenceCache};
use serde::Serialize;
use serde_json::{json, Value};
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use tokio::sync::broadcast;
use uuid::Uuid;

mod simulation;
mod studies;

/// A job interrupted this often in a row without a new checkpoint is dead-lettered.
const CHECKPOINT_EVERY: Duration = Duration::from_secs(1);
/// Reference runs of studies kept in memory (an h = k = 1/128 one holds about 50 MB).
const REFERENCES_KEPT: usize = 2;
/// File names inside a job's result directory.
pub const SUMMARY_FILE: &str = "summary.json";
/// Studies only: the paper-style table and the report plots.
pub const TABLE_FILE: &str = "summary.txt";
pub const REPORT_FILE: &str = "report.svg";
/// Sweeps only: the table of members as CSV.
pub const TABLE_CSV_FILE: &str = "table.csv";
const REPORTS_FILE: &str = "reports.json";
/// Error-estimate rows so far (simulations with `error_estimate`), saved with the reports.
const ESTIMATES_FILE: &str = "estimates.json";
/// Succeeded simulations: the state after the last step (u, ζ and the solvers' warm
/// starts, [`contact_core::output::stored::encode_state`]), what a continuation starts from
/// ([`crate::continuation`]).
pub const STATE_FILE: &str = "state.bin";
/// Target and adaptive studies only: the scene document of the chosen run (an adaptive
/// study's last cycle, on its final mesh stored as an uploaded mesh of the job's owner),
/// whose stored steps the job's fields, VTU, PVD and archive serve.
pub const CHOSEN_SCENE_FILE: &str = "chosen_scene.json";

/// A stored study document is a target study (`{"study": {"target": ...}}`) or an
/// adaptive one (`{"study": {"adapt": ...}}`): it also has the chosen run's fields.
pub fn has_chosen_run(doc: &serde_json::Value) -> bool {
    doc.get("study")
        .is_some_and(|s| study::is_target(s) || study::adapt::is_adapt(s))
}

/// A stored job document is a study when it has a top-level `study` object, or a sweep's
/// `sweep` (the scene of a simulation cannot: neither is a scene field).
pub fn is_study(doc: &serde_json::Value) -> bool {
    doc.get("study").is_some() || is_sweep(doc)
}

/// A stored sweep request `{"sweep": {...}}`: a study whose result is a table of members.
pub fn is_sweep(doc: &serde_json::Value) -> bool {
    doc.get("sweep").is_some()
}

/// The member of a stored job document that makes it a continuation.
pub const CONTINUED_FROM: &str = "continued_from";

/// The scene of a stored job document: the document without its [`CONTINUED_FROM`].
pub fn scene_of(doc: &Value) -> std::borrow::Cow<'_, Value> {
    match doc.get(CONTINUED_FROM) {
        None => std::borrow::Cow::Borrowed(doc),
        Some(_) => {
            let mut d = doc.clone();
            if let Some(o) = d.as_object_mut() {
                o.remove(CONTINUED_FROM);
            }
            std::borrow::Cow::Owned(d)
        }
    }
}

/// The parent link of a stored continuation: `{job, step, t, scene_hash}`.
pub fn parent_of(doc: &Value) -> Option<&Value> {
    doc.get(CONTINUED_FROM)
}

/// The parent's id of a stored continuation.
pub fn parent_id(doc: &Value) -> Option<Uuid> {
    parent_of(doc)?["job"].as_str()?.parse().ok()
}

/// Content hash of a result: the computation the stored document asks for (canonical JSON,
/// without the labels that change no number: the same computation under another name is the
/// same result), crate version, solver settings.
///
/// A continuation's parent is named by its computation hash (which determines its last
/// state), not by its job id: the same continuation of the same computation is one result.
pub fn scene_hash(scene: &Value) -> String {
    let mut computation = scene::computation(scene);
    if let Some(link) = computation
        .get_mut(CONTINUED_FROM)
        .and_then(Value::as_object_mut)
    {
        link.remove("job");
    }
    let key = json!({
        "scene": canonical(&computation),
        "version": env!("CARGO_PKG_VERSION"),
        "solver": SolverSettings::default(),
    });
    hex_sha256(key.to_string().as_bytes())
}

pub fn step_file(n: usize) -> String {
    format!("step_{n:06}.bin")
}

/// Parses `step_NNNNNN.bin`.
pub fn parse_step_file(name: &str) -> Option<usize> {
    name.strip_prefix("step_")?
        .strip_suffix(".bin")?
        .parse()
        .ok()
}

/// What subscribers of a job see.
#[derive(Debug, Clone, Serialize)]
pub struct JobEvent {
    pub status: JobStatus,
    pub step: usize,
    pub steps: usize,
    pub last_residual: Option<f64>,
    pub eta_s: Option<f64>,
}

impl JobEvent {
    /// The event describing a stored record (its persisted progress).
    pub fn from_record(r: &JobRecord) -> JobEvent {
        let eta_s = r.status.is_finished().then_some(0.0);
        JobEvent {
            status: r.status,
            step: r.progress.step,
            steps: r.progress.steps,
            last_residual: r.progress.last_residual,
            eta_s,
        }
    }
}

struct Live {
    progress: Progress,
    started: Instant,
    first_step: usize,
    cancel: Arc<AtomicBool>,
}

/// The worker pool and live job registry.
pub struct Runtime {
    pub store: Arc<dyn Store>,
    pub results: Arc<ResultFiles>,
    /// Uploaded meshes: what `domain.mesh` of a scene resolves to.
    pub meshes: Arc<Meshes>,
    pub config: Config,
    live: Mutex<HashMap<Uuid, Live>>,
    channels: Mutex<HashMap<Uuid, broadcast::Sender<JobEvent>>>,
    wake: (Mutex<u64>, Condvar),
    shutdown: AtomicBool,
    workers: Mutex<Vec<JoinHandle<()>>>,
    /// Time steps computed since start (metrics).
    pub steps_done: AtomicU64,
    pub running: AtomicUsize,
    /// Reference runs shared by studies of the same scene and resolution.
    pub references: ReferenceCache,
    /// The data directory's free space against `--min-free-disk`.
    pub disk: crate::disk::DiskGuard,
}

/// The problem type of a write that found the disk full: the job goes back in the queue
/// (see [`Runtime::run`]), it is never its error.
const DISK_FULL: &str = "/problems/disk-full";

/// A failed write of results: the disk full (see [`DISK_FULL`]), or a failure of the job.
fn write_failure(e: &std::io::Error) -> Problem {
    if crate::disk::is_full(e) {
        failure("disk full", &e.to_string()).with_type(DISK_FULL)
    } else {
        failure("cannot write results", &e.to_string())
    }
}

enum Outcome {
    Succeeded,
    Cancelled,
    /// Stopped by shutdown or lost lease: left `running` for a later resume.
    Interrupted,
    /// A sweep put back in the queue until its member jobs have ended (`studies`).
    Waiting,
}

impl Runtime {
    /// Starts `config.workers` worker threads.
    pub fn start(
        store: Arc<dyn Store>,
        results: Arc<ResultFiles>,
        meshes: Arc<Meshes>,
        config: Config,
    ) -> Arc<Runtime> {
        let rt = Arc::new(Runtime {
            store,
            results,
            meshes,
            live: Mutex::new(HashMap::new()),
            channels: Mutex::new(HashMap::new()),
            wake: (Mutex::new(0), Condvar::new()),
            shutdown: AtomicBool::new(false),
            workers: Mutex::new(Vec::new()),
            steps_done: AtomicU64::new(0),
            running: AtomicUsize::new(0),
            references: ReferenceCache::new(REFERENCES_KEPT),
            disk: crate::disk::DiskGuard::new(config.data_dir.clone(), config.min_free_disk),
            config,
        });
        let mut handles = Vec::new();
        for i in 0..rt.config.workers {
            let rt2 = rt.clone();
            let name = format!("{}-w{i}", rt.config.node);
            handles.push(
                std::thread::Builder::new()
                    .name(name.clone())
                    .spawn(move || rt2.worker_loop(&name))
                    .expect("spawn worker"),
            );
        }
        *rt.workers.lock().unwrap() = handles;
        if rt.config.workers > 0 {
            // Submissions on other nodes (shared store) wake this node's idle workers.
            let weak = Arc::downgrade(&rt);
            let wake: super::store::Wake = Arc::new(move || match weak.upgrade() {
                Some(rt) if !rt.shutdown.load(Ordering::SeqCst) => {
                    rt.notify();
                    true
                }
                _ => false,
            });
            if let Err(e) = rt.store.watch_for_work(wake) {
                tracing::warn!(
                    "cannot watch for new jobs (workers look every {:.1} s): {e}",
                    rt.idle_wait().as_secs_f64()
                );
            }
        }
        rt
    }

    /// How long an idle worker waits before looking for claimable jobs again when nobody
    /// woke it: new jobs wake it at once (the API here, or the store's notifications), so
    /// this only bounds how late a dead worker's job is noticed after its lease expired.
    fn idle_wait(&self) -> Duration {
        Duration::from_secs_f64((self.config.lease_s / 3.0).clamp(0.05, 10.0))
    }

    /// Wakes idle workers (a job was enqueued).
    pub fn notify(&self) {
        let (m, cv) = &self.wake;
        *m.lock().unwrap() += 1;
        cv.notify_all();
    }

    /// Stops the workers at their next step (running jobs are checkpointed and left
    /// `running`, to be resumed) and joins them.
    pub fn shutdown(&self) {
        self.shutdown.store(true, Ordering::SeqCst);
        self.notify();
        let handles = std::mem::take(&mut *self.workers.lock().unwrap());
        for h in handles {
            let _ = h.join();
        }
    }

    pub fn subscribe(&self, id: Uuid) -> broadcast::Receiver<JobEvent> {
        self.channel(id).subscribe()
    }

    fn channel(&self, id: Uuid) -> broadcast::Sender<JobEvent> {
        self.channels
            .lock()
            .unwrap()
            .entry(id)
            .or_insert_with(|| broadcast::channel(64).0)
            .clone()
    }

    fn publish(&self, id: Uuid, ev: JobEvent) {
        let tx = self.channels.lock().unwrap().get(&id).cloned();
        if let Some(tx) = tx {
            let _ = tx.send(ev);
        }
    }

    /// Records a running job's progress in memory and tells its subscribers (with an ETA).
    fn running_progress(&self, id: Uuid, progress: Progress) {
        let eta_s = {
            let mut live = self.live.lock().unwrap();
            live.get_mut(&id).and_then(|l| {
                l.progress = progress;
                eta(l)
            })
        };
        self.publish(
            id,
            JobEvent {
                status: JobStatus::Running,
                step: progress.step,
                steps: progress.steps,
                last_residual: progress.last_residual,
                eta_s,
            },
        );
    }

    /// Asks a running job to stop within one step.
    pub fn cancel(&self, id: Uuid) {
        if let Some(l) = self.live.lock().unwrap().get(&id) {
            l.cancel.store(true, Ordering::SeqCst);
        }
    }

    /// Live progress of a running job and its ETA in seconds.
    pub fn live_progress(&self, id: Uuid) -> Option<(Progress, Option<f64>)> {
        let live = self.live.lock().unwrap();
        let l = live.get(&id)?;
        Some((l.progress, eta(l)))
    }

    fn worker_loop(self: Arc<Self>, name: &str) {
        let mut low_logged = false;
        while !self.shutdown.load(Ordering::SeqCst) {
            // Below --min-free-disk the node takes no work: a job claimed now would only
            // go back to the queue at its first write.
            if let Err(low) = self.disk.check() {
                if !std::mem::replace(&mut low_logged, true) {
                    tracing::warn!(worker = name, "claiming nothing: {}", low.reason());
                }
                self.idle();
                continue;
            }
            if std::mem::replace(&mut low_logged, false) {
                tracing::info!(worker = name, "disk space is back; claiming jobs again");
            }
            match self
                .store
                .claim(name, self.config.lease_s, self.config.max_attempts)
            {
                Ok(Some(job)) => self.run(job, name),
                Ok(None) => self.idle(),
                Err(e) => {
                    tracing::error!(worker = name, "claim failed: {e}");
                    std::thread::sleep(Duration::from_secs(1));
                }
            }
        }
    }

    /// Waits until woken (a job was enqueued, shutdown) or [`Self::idle_wait`] passed.
    fn idle(&self) {
        let (m, cv) = &self.wake;
        let guard = m.lock().unwrap();
        let seen = *guard;
        let _ = cv.wait_timeout_while(guard, self.idle_wait(), |v| {
            *v == seen && !self.shutdown.load(Ordering::SeqCst)
        });
    }

    /// Puts a job whose write found the disk full back in the queue, its attempt not
    /// counted: its files past the last checkpoint are removed (the next claim writes them
    /// again from there) and the disk is measured afresh, so this node claims nothing more
    /// until space is back.
    fn requeue_full(&self, id: Uuid, worker: &str, detail: &str) {
        tracing::warn!("job {id}: the disk is full ({detail}); back to the queue");
        self.disk.note_full();
        let checkpoint = self
            .with_store_retry(|| self.store.load_checkpoint(id))
            .ok()
            .flatten()
            .map(|(step, _)| step);
        let partial = |name: &str| {
            parse_step_file(name).is_some_and(|n| checkpoint.is_none_or(|c| n > c))
                || (checkpoint.is_none() && name != SUMMARY_FILE)
        };
        if let Err(e) = self.results.remove_where(id, partial) {
            tracing::warn!("job {id}: cannot remove its partial results: {e}");
        }
        match self.with_store_retry(|| self.store.requeue(id, worker)) {
            Ok(true) => {}
            Ok(false) => tracing::warn!("job {id} was no longer this worker's to requeue"),
            Err(e) => tracing::error!("cannot requeue job {id}: {e}"),
        }
    }

    /// Runs one claimed job to its end (or interruption) inside a `job` span carrying its
    /// id, attempt, kind and worker, so that a node's log can be filtered by job.
    fn run(&self, job: JobRecord, worker: &str) {
        let id = job.id;
        let kind = if is_study(&job.scene) {
            "study"
        } else {
            "simulation"
        };
        let span =
            tracing::info_span!("job", %id, attempt = job.attempt, kind = %kind, worker = %worker);
        let _entered = span.enter();
        let cancel = Arc::new(AtomicBool::new(job.cancel_requested));
        self.live.lock().unwrap().insert(
            id,
            Live {
                progress: job.progress,
                started: Instant::now(),
                first_step: job.progress.step,
                cancel: cancel.clone(),
            },
        );
        self.running.fetch_add(1, Ordering::SeqCst);
        let keeper =
            super::lease::Keeper::start(self.store.clone(), id, worker, self.config.lease_s);
        let started = Instant::now();
        let outcome = if is_sweep(&job.scene) {
            self.execute_sweep(&job, worker)
        } else if is_study(&job.scene) {
            self.execute_study(&job, worker, &cancel)
        } else {
            self.execute(&job, worker, &cancel)
        };
        self.charge(&job.owner, started.elapsed().as_secs_f64());
        // A sweep back in the queue keeps its subscribers: they follow it until it ends.
        let waiting = matches!(outcome, Ok(Outcome::Waiting));
        let final_status = match outcome {
            Ok(Outcome::Succeeded) => Some((JobStatus::Succeeded, None)),
            Ok(Outcome::Cancelled) => Some((JobStatus::Cancelled, None)),
            Ok(Outcome::Interrupted | Outcome::Waiting) => None,
            Err(problem) if problem.type_ == DISK_FULL => {
                self.requeue_full(id, worker, &problem.detail);
                None
            }
            Err(problem) => Some((JobStatus::Failed, Some(problem))),
        };
        let progress = self
            .live
            .lock()
            .unwrap()
            .remove(&id)
            .map(|l| l.progress)
            .unwrap_or(job.progress);
        self.running.fetch_sub(1, Ordering::SeqCst);
        if let Some((status, error)) = final_status {
            // The lease is kept until the end is recorded: were the store unreachable for
            // longer than a lease, another worker would otherwise compute the job again.
            let _ = self.with_store_retry(|| self.store.set_progress(id, progress));
            let error = error.map(|p| p.to_json());
            match self.with_store_retry(|| self.store.finish(id, status, error.clone())) {
                Ok(()) => tracing::info!("job {id} {} (attempt {})", status.as_str(), job.attempt),
                Err(e) => tracing::error!("cannot record the end of job {id}: {e}"),
            }
            if let Some(sweep) = job.sweep {
                // A member ended: its sweep's progress moves, and the sweep may be claimable.
                self.refresh_sweep_progress(sweep);
                self.notify();
            }
            if status != JobStatus::Succeeded {
                // No partial results left on the disk: a failed job keeps its error (in the
                // store) and its summary, if it wrote one.
                if let Err(e) = self.results.remove_where(id, |n| n != SUMMARY_FILE) {
                    tracing::warn!("job {id}: cannot remove its results: {e}");
                }
            }
            drop(keeper);
            self.publish(
                id,
                JobEvent {
                    status,
                    step: progress.step,
                    steps: progress.steps,
                    last_residual: progress.last_residual,
                    eta_s: Some(0.0),
                },
            );
        }
        if !waiting {
            self.channels.lock().unwrap().remove(&id);
        }
    }

    /// Adds an attempt's worker-seconds to its owner's compute of the day (the quota of
    /// `crate::auth::quota`); the anonymous owner has no quota and is not counted.
    fn charge(&self, owner: &str, seconds: f64) {
        if owner.is_empty() {
            return;
        }
        let day = crate::store::owners::day_of(crate::store::now());
        // Not retried: an addition whose outcome is unknown must not be counted twice.
        if let Err(e) = self.store.add_compute(owner, day, seconds) {
            tracing::warn!("cannot count {seconds:.1} s of compute for {owner}: {e}");
        }
    }

    /// Renews the lease; `Some` if the job is no longer this worker's to compute: cancelled
    /// meanwhile, or (its lease having expired) claimed by another worker. A store that
    /// cannot be reached keeps the job going (the lease keeper retries).
    fn lost(&self, id: Uuid, worker: &str) -> Option<Outcome> {
        match self.store.heartbeat(id, worker, self.config.lease_s) {
            Ok(true) => None,
            Ok(false) => {
                let rec = self.store.get(id).ok().flatten();
                Some(if rec.is_some_and(|r| r.cancel_requested) {
                    Outcome::Cancelled
                } else {
                    tracing::warn!("job {id} was taken over by another worker; stopping");
                    Outcome::Interrupted
                })
            }
            Err(e) => {
                tracing::warn!("heartbeat of {id} failed: {e}");
                None
            }
        }
    }

    /// Runs an idempotent store operation, retrying while the store is unavailable (a
    /// shared database restarting) with a backoff up to 5 s, until it succeeds, fails for
    /// another reason, or the server shuts down.
    fn with_store_retry<T>(
        &self,
        mut op: impl FnMut() -> Result<T, StoreError>,
    ) -> Result<T, StoreError> {
        let mut backoff = Duration::from_millis(100);
        loop {
            match op() {
                Err(StoreError::Unavailable(e)) if !self.shutdown.load(Ordering::SeqCst) => {
                    tracing::warn!("store unavailable ({e}); retrying in {backoff:?}");
                    std::thread::sleep(backoff);
                    backoff = (backoff * 2).min(Duration::from_secs(5));
                }
                other => return other,
            }
        }
    }
}

fn eta(l: &Live) -> Option<f64> {
    let done = l.progress.step.saturating_sub(l.first_step);
    (done > 0).then(|| {
        l.started.elapsed().as_secs_f64() / done as f64
            * (l.progress.steps - l.progress.step) as f64
    })
}

/// A job that failed through no fault of its scene (500).
fn failure(title: &'static str, detail: &str) -> Problem {
    Problem::new(StatusCode::INTERNAL_SERVER_ERROR, title, detail)
}

fn solve_problem(e: &SolveError) -> Problem {
    match e {
        SolveError::Smallness(_) => Problem::new(
            StatusCode::UNPROCESSABLE_ENTITY,
            "smallness condition violated",
            e.to_string(),
        )
        .with_type("/problems/smallness"),
        // Scene data unusable where the scheme evaluates it (e.g. a load formula infinite at
        // a quadrature point between validation's samples): the scene's fault, at its field.
        SolveError::Data { pointer, message } => {
            let mut p = Problem::field(
                StatusCode::UNPROCESSABLE_ENTITY,
                "invalid scene data",
                pointer,
                message.clone(),
            )
            .with_type("/problems/scene-data");
            p.detail = e.to_string();
            p
        }
        SolveError::Memory(m) => Problem::field(
            StatusCode::UNPROCESSABLE_ENTITY,
            "the job does not fit the memory limit",
            m.pointer(),
            m.to_string(),
        )
        .with_type("/problems/memory"),
        _ => failure("simulation failed", &e.to_string()).with_type("/problems/solver"),
    }
}
