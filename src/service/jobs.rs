//! Job execution: a fixed pool of worker threads (never the async runtime's threads) claims
//! jobs from the store, runs the time loop, writes stored steps and the summary atomically,
//! checkpoints (u, ζ, step) about once a second, checks cancellation every step, and
//! publishes progress to live subscribers (SSE).
//!
//! Restart safety: a job's state is (u, ζ, step) plus the per-step reports so far; a worker
//! that dies leaves the job `running` with an expiring lease, and the next claim resumes it
//! from the last checkpoint.

use super::store::results::ResultFiles;
use super::store::{JobRecord, JobStatus, Progress, Store, StoreError};
use super::Config;
use crate::output::stored::{decode_state, encode_state, encode_step};
use crate::output::Summary;
use crate::scene;
use crate::solve::stepper::{Simulation, StepReport};
use crate::solve::{SolveError, SolverSettings};
use serde::Serialize;
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use tokio::sync::broadcast;
use uuid::Uuid;

/// Lease of a claimed job; renewed while it runs (`lease::Keeper`) and at checkpoints.
const LEASE_S: f64 = 30.0;
/// A job interrupted this often in a row without a new checkpoint is dead-lettered.
const MAX_ATTEMPTS: u32 = 3;
const CHECKPOINT_EVERY: Duration = Duration::from_secs(1);
/// File names inside a job's result directory.
pub const SUMMARY_FILE: &str = "summary.json";
const REPORTS_FILE: &str = "reports.json";

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
    pub config: Config,
    live: Mutex<HashMap<Uuid, Live>>,
    channels: Mutex<HashMap<Uuid, broadcast::Sender<JobEvent>>>,
    wake: (Mutex<u64>, Condvar),
    shutdown: AtomicBool,
    workers: Mutex<Vec<JoinHandle<()>>>,
    /// Time steps computed since start (metrics).
    pub steps_done: AtomicU64,
    pub running: AtomicUsize,
}

enum Outcome {
    Succeeded,
    Cancelled,
    /// Stopped by shutdown or lost lease: left `running` for a later resume.
    Interrupted,
}

impl Runtime {
    /// Starts `config.workers` worker threads.
    pub fn start(store: Arc<dyn Store>, results: Arc<ResultFiles>, config: Config) -> Arc<Runtime> {
        let rt = Arc::new(Runtime {
            store,
            results,
            config,
            live: Mutex::new(HashMap::new()),
            channels: Mutex::new(HashMap::new()),
            wake: (Mutex::new(0), Condvar::new()),
            shutdown: AtomicBool::new(false),
            workers: Mutex::new(Vec::new()),
            steps_done: AtomicU64::new(0),
            running: AtomicUsize::new(0),
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
        rt
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
        while !self.shutdown.load(Ordering::SeqCst) {
            match self.store.claim(name, LEASE_S, MAX_ATTEMPTS) {
                Ok(Some(job)) => self.run(job, name),
                Ok(None) => {
                    let (m, cv) = &self.wake;
                    let guard = m.lock().unwrap();
                    let seen = *guard;
                    let _ = cv.wait_timeout_while(guard, Duration::from_millis(500), |v| {
                        *v == seen && !self.shutdown.load(Ordering::SeqCst)
                    });
                }
                Err(e) => {
                    eprintln!("contact-sim: {name}: claim failed: {e}");
                    std::thread::sleep(Duration::from_secs(1));
                }
            }
        }
    }

    fn run(&self, job: JobRecord, worker: &str) {
        let id = job.id;
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
        let keeper = super::lease::Keeper::start(self.store.clone(), id, worker, LEASE_S);
        let outcome = self.execute(&job, worker, &cancel);
        drop(keeper);
        let final_status = match outcome {
            Ok(Outcome::Succeeded) => Some((JobStatus::Succeeded, None)),
            Ok(Outcome::Cancelled) => Some((JobStatus::Cancelled, None)),
            Ok(Outcome::Interrupted) => None,
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
            let _ = self.store.set_progress(id, progress);
            if let Err(e) = self.store.finish(id, status, error) {
                eprintln!("contact-sim: cannot record the end of job {id}: {e}");
            }
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
        self.channels.lock().unwrap().remove(&id);
    }

    fn execute(
        &self,
        job: &JobRecord,
        worker: &str,
        cancel: &AtomicBool,
    ) -> Result<Outcome, serde_json::Value> {
        let id = job.id;
        let problem = scene::validate(&job.scene)
            .map_err(|e| problem_json(500, "stored scene no longer validates", &e.to_string()))?;
        let steps = problem.steps;
        let output = problem.output;
        let mut sim =
            Simulation::new(problem, SolverSettings::default()).map_err(|e| solve_problem(&e))?;
        let mut reports: Vec<StepReport> = Vec::new();
        if let Some(resumed) = self
            .resume(id, &mut sim)
            .map_err(|e| problem_json(500, "checkpoint unreadable", &e))?
        {
            reports = resumed;
        }
        let solve_start = Instant::now();
        let mut last_checkpoint = Instant::now();
        let io = |e: std::io::Error| problem_json(500, "cannot write results", &e.to_string());
        while !sim.finished() {
            if cancel.load(Ordering::SeqCst) {
                return Ok(Outcome::Cancelled);
            }
            if self.shutdown.load(Ordering::SeqCst) {
                self.checkpoint(id, &sim, &reports)
                    .map_err(|e| problem_json(500, "checkpoint failed", &e.to_string()))?;
                return Ok(Outcome::Interrupted);
            }
            let r = sim.step().map_err(|e| solve_problem(&e))?;
            if output.stores(r.n, steps) {
                self.results
                    .write_atomic(id, &step_file(r.n), &encode_step(&sim.fields()))
                    .map_err(io)?;
            }
            let residual = r
                .velocity
                .residual
                .max(r.damage.map_or(0.0, |d| d.residual));
            let progress = Progress {
                step: r.n,
                steps,
                last_residual: Some(residual),
            };
            reports.push(r);
            self.steps_done.fetch_add(1, Ordering::Relaxed);
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
                    steps,
                    last_residual: progress.last_residual,
                    eta_s,
                },
            );
            if last_checkpoint.elapsed() >= CHECKPOINT_EVERY && !sim.finished() {
                last_checkpoint = Instant::now();
                self.checkpoint(id, &sim, &reports)
                    .map_err(|e| problem_json(500, "checkpoint failed", &e.to_string()))?;
                match self.store.heartbeat(id, worker, LEASE_S) {
                    Ok(true) => {}
                    Ok(false) => {
                        // Cancelled meanwhile, or the lease went to another worker.
                        let rec = self.store.get(id).ok().flatten();
                        return Ok(if rec.is_some_and(|r| r.cancel_requested) {
                            Outcome::Cancelled
                        } else {
                            Outcome::Interrupted
                        });
                    }
                    Err(e) => eprintln!("contact-sim: heartbeat of {id} failed: {e}"),
                }
            }
        }
        let summary = Summary::new(&sim, reports, solve_start.elapsed().as_secs_f64());
        let text = serde_json::to_vec_pretty(&summary).expect("summary serialises");
        self.results
            .write_atomic(id, SUMMARY_FILE, &text)
            .map_err(io)?;
        Ok(Outcome::Succeeded)
    }

    /// Saves the per-step reports, then (u, ζ, step) in the store. A crash between the two
    /// leaves more reports than the checkpoint step; `resume` truncates them.
    fn checkpoint(
        &self,
        id: Uuid,
        sim: &Simulation,
        reports: &[StepReport],
    ) -> Result<(), StoreError> {
        let bytes = serde_json::to_vec(reports).expect("reports serialise");
        self.results.write_atomic(id, REPORTS_FILE, &bytes)?;
        self.store
            .checkpoint(id, sim.state.step, &encode_state(&sim.state))?;
        self.store.set_progress(
            id,
            Progress {
                step: sim.state.step,
                steps: sim.problem.steps,
                last_residual: None,
            },
        )
    }

    /// Restores the last checkpoint, if any; returns the reports up to it.
    fn resume(&self, id: Uuid, sim: &mut Simulation) -> Result<Option<Vec<StepReport>>, String> {
        let Some((step, bytes)) = self.store.load_checkpoint(id).map_err(|e| e.to_string())? else {
            return Ok(None);
        };
        let state = decode_state(&bytes).map_err(|e| e.to_string())?;
        let reports: Vec<StepReport> = match self
            .results
            .read(id, REPORTS_FILE)
            .map_err(|e| e.to_string())?
        {
            Some(b) => serde_json::from_slice(&b).map_err(|e| e.to_string())?,
            None => Vec::new(),
        };
        if state.step != step
            || reports.len() < step
            || state.u.len() != sim.state.u.len()
            || state.zeta.len() != sim.state.zeta.len()
        {
            // Inconsistent checkpoint: start over rather than produce a wrong result.
            return Ok(None);
        }
        let mut reports = reports;
        reports.truncate(step);
        sim.restore(state);
        Ok(Some(reports))
    }
}

fn eta(l: &Live) -> Option<f64> {
    let done = l.progress.step.saturating_sub(l.first_step);
    (done > 0).then(|| {
        l.started.elapsed().as_secs_f64() / done as f64
            * (l.progress.steps - l.progress.step) as f64
    })
}

pub fn problem_json(status: u16, title: &str, detail: &str) -> serde_json::Value {
    serde_json::json!({"type": "about:blank", "title": title, "status": status, "detail": detail})
}

fn solve_problem(e: &SolveError) -> serde_json::Value {
    match e {
        SolveError::Smallness(_) => {
            let mut p = problem_json(422, "smallness condition violated", &e.to_string());
            p["type"] = "/problems/smallness".into();
            p
        }
        _ => {
            let mut p = problem_json(500, "simulation failed", &e.to_string());
            p["type"] = "/problems/solver".into();
            p
        }
    }
}
