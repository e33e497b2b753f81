//! A study job ([`contact_core::study::request`]): run under the node's per-job limits, with
//! progress over all its runs' steps, the lease renewed from the computing threads, and a
//! target study's chosen run writing its stored steps as a simulation does.

use super::{failure, solve_problem, write_failure, Outcome, Runtime, CHECKPOINT_EVERY};
use super::{is_study, parse_step_file, step_file, STATE_FILE, TABLE_CSV_FILE};
use super::{CHOSEN_SCENE_FILE, REPORT_FILE, SUMMARY_FILE, TABLE_FILE};
use crate::problem::Problem;
use crate::store::results::ResultFiles;
use crate::store::{JobRecord, Progress};
use axum::http::StatusCode;
use contact_core::output::stored::decode_state;
use contact_core::output::stored::encode_step;
use contact_core::solve::stepper::State;
use contact_core::solve::SolverSettings;
use contact_core::study::{self, StudyError};
use std::ops::ControlFlow;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;
use std::time::Instant;
use uuid::Uuid;

impl Runtime {
    /// A study (ladder or target, [`study::request`]): no per-step checkpoints (a resumed
    /// study starts over; its reference may still be cached), progress over all runs' steps,
    /// the lease renewed about once a second from the computing threads, under the per-job
    /// limits it was admitted under. A target study's chosen run writes its stored steps as
    /// a simulation does; an unreachable target fails the job with a 422 problem at
    /// `/study/target/error`.
    pub(super) fn execute_study(
        &self,
        job: &JobRecord,
        worker: &str,
        cancel: &AtomicBool,
    ) -> Result<Outcome, Problem> {
        let id = job.id;
        let (request, _) = match job.scene.get("sweep") {
            Some(sweep) => study::request::parse_sweep(sweep, "/sweep", &*self.meshes),
            None => study::request::parse(&job.scene["study"], "/study", &*self.meshes),
        }
        .map_err(|e| failure("stored study no longer validates", &e.to_string()))?;
        // A sweep's member equal to a simulation its owner has computed (the same content
        // hash) is taken from that job's summary and last state.
        let known = |scene: &serde_json::Value| -> Option<(serde_json::Value, State)> {
            let hash = super::scene_hash(scene);
            let rec = self.store.find_succeeded_for(&job.owner, &hash).ok()??;
            if is_study(&rec.scene) {
                return None;
            }
            let summary = self.results.read(rec.id, SUMMARY_FILE).ok()??;
            let state = self.results.read(rec.id, STATE_FILE).ok()??;
            Some((
                serde_json::from_slice(&summary).ok()?,
                decode_state(&state).ok()?,
            ))
        };
        let mut sink = StepFiles {
            results: &self.results,
            id,
        };
        self.run_study_job(id, worker, cancel, |progress| {
            let cx = study::request::Context {
                cache: &self.references,
                threads: self.config.threads_per_job,
                settings: SolverSettings::default(),
                limits: self.config.job_limits(),
                progress,
                sink: &mut sink,
            };
            let outcome = request.execute_known(cx, &known)?;
            let pretty = |v: &serde_json::Value| {
                serde_json::to_vec_pretty(v).expect("a JSON value serialises")
            };
            let mut files = Vec::new();
            if let Some(scene) = outcome.chosen_scene() {
                files.push((CHOSEN_SCENE_FILE, pretty(scene)));
            }
            if let study::request::Outcome::Sweep(r) = &outcome {
                files.push((TABLE_CSV_FILE, r.csv().into_bytes()));
            }
            files.push((TABLE_FILE, outcome.text_table().into_bytes()));
            files.push((REPORT_FILE, outcome.report_svg().into_bytes()));
            files.push((SUMMARY_FILE, pretty(&outcome.to_json())));
            Ok(files)
        })
    }

    /// What every study job shares: `run` computes with a progress hook that counts steps,
    /// renews the lease about once a second and stops on cancel, shutdown or a lost lease;
    /// the files it returns are written in order (the summary last: its presence means the
    /// result is complete). A stopped study is cancelled, interrupted or taken over; an
    /// unreachable target is a 422 problem at `/study/target/error`.
    fn run_study_job(
        &self,
        id: Uuid,
        worker: &str,
        cancel: &AtomicBool,
        run: impl FnOnce(&StudyProgress) -> Result<Vec<(&'static str, Vec<u8>)>, StudyError>,
    ) -> Result<Outcome, Problem> {
        let last_beat = Mutex::new(Instant::now());
        // Why a heartbeat stopped the study (cancelled, or taken over by another worker).
        let stopped: Mutex<Option<Outcome>> = Mutex::new(None);
        let progress = |done: usize, total: usize| {
            if cancel.load(Ordering::SeqCst) || self.shutdown.load(Ordering::SeqCst) {
                return ControlFlow::Break(());
            }
            self.steps_done.fetch_add(1, Ordering::Relaxed);
            let p = Progress {
                step: done,
                steps: total,
                last_residual: None,
            };
            self.running_progress(id, p);
            let mut beat = last_beat.lock().unwrap();
            if beat.elapsed() >= CHECKPOINT_EVERY {
                *beat = Instant::now();
                let _ = self.store.set_progress(id, p);
                if let Some(stop) = self.lost(id, worker) {
                    *stopped.lock().unwrap() = Some(stop);
                    return ControlFlow::Break(());
                }
            }
            ControlFlow::Continue(())
        };
        match run(&progress) {
            Ok(files) => {
                for (name, bytes) in files {
                    self.results
                        .write_atomic(id, name, &bytes)
                        .map_err(|e| write_failure(&e))?;
                }
                Ok(Outcome::Succeeded)
            }
            Err(StudyError::Cancelled) => Ok(if cancel.load(Ordering::SeqCst) {
                Outcome::Cancelled
            } else {
                // A heartbeat's verdict, or else shutting down: a cancel requested through
                // another node meanwhile still counts.
                let stopped = stopped.into_inner().unwrap();
                stopped
                    .or_else(|| self.lost(id, worker))
                    .unwrap_or(Outcome::Interrupted)
            }),
            Err(e @ StudyError::Unreachable { .. }) => Err(Problem::field(
                StatusCode::UNPROCESSABLE_ENTITY,
                "target out of reach",
                "/study/target/error",
                e.to_string(),
            )
            .with_type("/problems/target-unreachable")),
            Err(StudyError::Output(e)) => Err(write_failure(&e)),
            Err(StudyError::Run(contact_core::run::RunError::Solve(e))) => Err(solve_problem(&e)),
            Err(e) => Err(failure("study failed", &e.to_string())),
        }
    }
}

/// The chosen run of a target study writes its stored steps as a simulation does.
struct StepFiles<'a> {
    results: &'a ResultFiles,
    id: Uuid,
}

impl study::target::Sink for StepFiles<'_> {
    fn restart(&mut self) -> std::io::Result<()> {
        self.results
            .remove_where(self.id, |name| parse_step_file(name).is_some())
    }

    fn step(&mut self, fields: &contact_core::solve::stepper::StepFields) -> std::io::Result<()> {
        self.results
            .write_atomic(self.id, &step_file(fields.n), &encode_step(fields))
    }
}

/// The progress hook of a study job: (steps done, steps in all) after every step of every
/// run; `Break` stops the study.
type StudyProgress<'a> = dyn Fn(usize, usize) -> ControlFlow<()> + Sync + 'a;
