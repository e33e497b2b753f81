//! A study job ([`contact_core::study::request`]): run under the node's per-job limits, with
//! progress over all its runs' steps, the lease renewed from the computing threads, and a
//! target study's chosen run writing its stored steps as a simulation does.
//!
//! A sweep ([`contact_core::study::sweep`]) computes nothing itself: its members are
//! ordinary simulation jobs of its owner ([`Runtime::execute_sweep`]), queued on the same
//! workers as every other job, and the sweep waits in the queue until they have ended.

use super::{failure, solve_problem, write_failure, Outcome, Runtime, CHECKPOINT_EVERY};
use super::{is_study, parse_step_file, step_file, STATE_FILE, TABLE_CSV_FILE};
use super::{CHOSEN_SCENE_FILE, REPORT_FILE, SUMMARY_FILE, TABLE_FILE};
use crate::problem::Problem;
use crate::store::results::ResultFiles;
use crate::store::{Enqueued, JobRecord, JobStatus, NewJob, Progress};
use axum::http::StatusCode;
use contact_core::output::stored::decode_state;
use contact_core::output::stored::encode_step;
use contact_core::solve::SolverSettings;
use contact_core::study::sweep::{Computed, SweepSpec};
use contact_core::study::{self, StudyError};
use std::ops::ControlFlow;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;
use std::time::Instant;
use uuid::Uuid;

impl Runtime {
    /// A ladder, target or adaptive study ([`study::request`]): no per-step checkpoints (a resumed
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
        let (request, _) = study::request::parse(&job.scene["study"], "/study", &*self.meshes)
            .map_err(|e| failure("stored study no longer validates", &e.to_string()))?;
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
            let outcome = request.execute(cx)?;
            let pretty = |v: &serde_json::Value| {
                serde_json::to_vec_pretty(v).expect("a JSON value serialises")
            };
            let mut files = Vec::new();
            let mut summary = outcome.to_json();
            // An adaptive mesh (an adaptive study's final one, or the one a target study took)
            // becomes an uploaded mesh of the job's owner: the study's run is then served as
            // a simulation on it, and the file is downloadable.
            if let Some(msh) = outcome.final_msh() {
                let (mesh, _) = self
                    .meshes
                    .upload_for(&job.owner, msh.as_bytes())
                    .map_err(|p| StudyError::Output(std::io::Error::other(p.detail)))?;
                let scene = outcome
                    .scene_on(&mesh.id)
                    .expect("a final mesh has its scene");
                files.push((CHOSEN_SCENE_FILE, pretty(&scene)));
                summary["final_mesh"] = serde_json::json!({
                    "id": mesh.id,
                    "file": format!("/meshes/{}/file", mesh.id),
                });
            } else if let Some(scene) = outcome.chosen_scene() {
                files.push((CHOSEN_SCENE_FILE, pretty(scene)));
            }
            files.push((TABLE_FILE, outcome.text_table().into_bytes()));
            files.push((REPORT_FILE, outcome.report_svg().into_bytes()));
            files.push((SUMMARY_FILE, pretty(&summary)));
            Ok(files)
        })
    }

    /// A sweep: each member is a simulation job of the sweep's owner — the one this sweep
    /// created for it earlier, else a job of the same computation that already succeeded
    /// for that owner (as `POST /jobs` of the member's scene would answer), else a new one,
    /// queued like any job and naming the sweep. While one of them is queued or running, the sweep
    /// records its members and its progress and goes back to the queue, where the store
    /// does not claim it again before they have ended ([`crate::store::Store::claim`]);
    /// a worker is never held waiting. Every claim looks afresh, so a restart at any point
    /// neither loses nor duplicates a member. Once all have succeeded, the table, CSV, plot
    /// and summary are assembled from their summaries and last states; a member that failed
    /// or was cancelled fails the sweep with a problem naming it, and the sweep's other
    /// unfinished members are cancelled.
    pub(super) fn execute_sweep(&self, job: &JobRecord, worker: &str) -> Result<Outcome, Problem> {
        let id = job.id;
        let (spec, _) = study::sweep::parse_with(&job.scene["sweep"], "/sweep", &*self.meshes)
            .map_err(|e| failure("stored sweep no longer validates", &e.to_string()))?;
        let store_failed = |e: crate::store::StoreError| {
            tracing::warn!("sweep {id}: store error ({e}); left for a later claim");
            Outcome::Interrupted
        };
        if job.cancel_requested {
            self.cancel_members(id);
            return Ok(Outcome::Cancelled);
        }
        let mut created = match self.with_store_retry(|| self.store.sweep_members(id)) {
            Ok(c) => c,
            Err(e) => return Ok(store_failed(e)),
        };
        // Each member's job and whether this sweep created it.
        let mut members: Vec<(JobRecord, bool)> = Vec::with_capacity(spec.members.len());
        for (i, m) in spec.members.iter().enumerate() {
            let hash = super::scene_hash(&m.scene);
            if let Some(r) = created.iter().find(|r| r.scene_hash == hash) {
                members.push((r.clone(), true));
                continue;
            }
            let earlier =
                match self.with_store_retry(|| self.store.find_succeeded_for(&job.owner, &hash)) {
                    Ok(r) => r.filter(|r| !is_study(&r.scene)),
                    Err(e) => return Ok(store_failed(e)),
                };
            if let Some(r) = earlier {
                members.push((r, false));
                continue;
            }
            let rec = match self.enqueue_member(job, &spec, i, hash)? {
                Ok(rec) => rec,
                Err(e) => return Ok(store_failed(e)),
            };
            created.push(rec.clone());
            members.push((rec, true));
        }
        let ids: Vec<Uuid> = members.iter().map(|(r, _)| r.id).collect();
        if let Err(e) = self.with_store_retry(|| self.store.set_members(id, &ids)) {
            return Ok(store_failed(e));
        }
        if let Some((i, (r, _))) = members.iter().enumerate().find(|(_, (r, own))| {
            *own && matches!(r.status, JobStatus::Failed | JobStatus::Cancelled)
        }) {
            self.cancel_members(id);
            return Err(member_failed(&spec, i, r));
        }
        let progress = sweep_progress(job.progress.steps, members.iter().map(|(r, _)| r));
        self.running_progress(id, progress);
        if members.iter().any(|(r, _)| !r.status.is_finished()) {
            self.notify();
            let _ = self.with_store_retry(|| self.store.set_progress(id, progress));
            match self.with_store_retry(|| self.store.requeue(id, worker)) {
                Ok(true) => {}
                Ok(false) => tracing::warn!("sweep {id} was no longer this worker's to requeue"),
                Err(e) => return Ok(store_failed(e)),
            }
            // A cancel requested meanwhile made the requeued sweep cancelled: its members
            // go with it.
            if let Ok(Some(r)) = self.store.get(id) {
                if r.status == JobStatus::Cancelled {
                    self.cancel_members(id);
                }
            }
            return Ok(Outcome::Waiting);
        }
        let mut computed = Vec::with_capacity(members.len());
        for (i, (r, own)) in members.iter().enumerate() {
            let read = |name: &str| self.results.read(r.id, name).ok().flatten();
            let (Some(summary), Some(state)) = (read(SUMMARY_FILE), read(STATE_FILE)) else {
                return Err(failure(
                    "sweep member unreadable",
                    &format!(
                        "member {i} ({}): job {} has no stored summary and last state",
                        spec.describe(&spec.members[i]),
                        r.id
                    ),
                ));
            };
            computed.push(Computed {
                summary: serde_json::from_slice(&summary)
                    .map_err(|e| failure("sweep member unreadable", &e.to_string()))?,
                state: decode_state(&state)
                    .map_err(|e| failure("sweep member unreadable", &e.to_string()))?,
                computed: *own,
                job: r.id.to_string(),
            });
        }
        let seconds = job
            .started_at
            .map_or(0.0, |t| (crate::store::now() - t).max(0.0));
        let result = study::sweep::assemble(&spec, computed, seconds)
            .map_err(|e| failure("sweep member unreadable", &e))?;
        let outcome = study::request::Outcome::Sweep(Box::new(result));
        let pretty =
            |v: &serde_json::Value| serde_json::to_vec_pretty(v).expect("a JSON value serialises");
        let mut files = Vec::new();
        if let study::request::Outcome::Sweep(r) = &outcome {
            files.push((TABLE_CSV_FILE, r.csv().into_bytes()));
        }
        files.push((TABLE_FILE, outcome.text_table().into_bytes()));
        files.push((REPORT_FILE, outcome.report_svg().into_bytes()));
        files.push((SUMMARY_FILE, pretty(&outcome.to_json())));
        for (name, bytes) in files {
            self.results
                .write_atomic(id, name, &bytes)
                .map_err(|e| write_failure(&e))?;
        }
        self.running_progress(
            id,
            Progress {
                step: progress.steps,
                ..progress
            },
        );
        Ok(Outcome::Succeeded)
    }

    /// Enqueues member `i` of `spec` as a job of the sweep's owner naming the sweep, held to
    /// the per-job limits as a `POST /jobs` of its scene would be (the sweep's admission
    /// checked each member against them already). The outer error fails the sweep; the
    /// inner one is the store's.
    fn enqueue_member(
        &self,
        sweep: &JobRecord,
        spec: &SweepSpec,
        i: usize,
        hash: String,
    ) -> Result<Result<JobRecord, crate::store::StoreError>, Problem> {
        let m = &spec.members[i];
        let at = contact_core::admission::Pointers {
            mesh: "/sweep/scene/mesh".into(),
            steps: "/sweep/scene/time".into(),
            output: "/sweep/scene/output".into(),
            solver: Some("/sweep/scene/solver/linear".into()),
        };
        let fit = contact_core::admission::check_run(&m.problem, &self.config.job_limits(), &at)
            .map_err(|e| Problem::over_limit(&e))?;
        let new = NewJob {
            scene: m.scene.clone(),
            scene_hash: hash,
            steps: m.problem.steps,
            idempotency_key: None,
            request_hash: None,
            mesh: crate::meshes::mesh_ref(&m.scene),
            memory: Some(crate::store::MemoryPrediction {
                linear_path: fit.path,
                predicted_bytes: fit.memory_bytes,
            }),
        };
        let enqueued = self.with_store_retry(|| {
            self.store
                .enqueue_in(&sweep.owner, fit.stored_bytes, new.clone(), Some(sweep.id))
        });
        Ok(match enqueued {
            Ok(Enqueued::New(rec) | Enqueued::Existing(rec)) => Ok(rec),
            Ok(Enqueued::NoMesh(mesh)) => {
                return Err(Problem::invalid_field(
                    "/sweep/scene/domain/mesh",
                    crate::meshes::unknown_mesh(&mesh),
                ))
            }
            Ok(Enqueued::KeyConflict(rec)) => Ok(rec),
            Err(e) => Err(e),
        })
    }

    /// Cancels the unfinished members `sweep` created (a member taken from an earlier job
    /// of its owner is that job, finished, and never cancelled).
    pub fn cancel_members(&self, sweep: Uuid) {
        let members = match self.with_store_retry(|| self.store.sweep_members(sweep)) {
            Ok(m) => m,
            Err(e) => {
                tracing::warn!("sweep {sweep}: cannot list its members to cancel: {e}");
                return;
            }
        };
        for m in members.iter().filter(|m| !m.status.is_finished()) {
            if let Err(e) = self.with_store_retry(|| self.store.request_cancel(m.id)) {
                tracing::warn!("sweep {sweep}: cannot cancel member {}: {e}", m.id);
            }
            self.cancel(m.id);
        }
    }

    /// Records a sweep's progress from its members' (after one of them ended).
    pub(super) fn refresh_sweep_progress(&self, sweep: Uuid) {
        let Ok(Some(rec)) = self.with_store_retry(|| self.store.get(sweep)) else {
            return;
        };
        if rec.status.is_finished() {
            return;
        }
        if let Some(p) = self.sweep_members_progress(&rec) {
            let _ = self.with_store_retry(|| self.store.set_progress(sweep, p));
        }
    }

    /// A sweep's progress now: its members' steps done (live on this node where they run)
    /// out of all; None before the sweep has recorded its members.
    pub fn sweep_members_progress(&self, sweep: &JobRecord) -> Option<Progress> {
        if sweep.members.is_empty() {
            return None;
        }
        let mut records: Vec<JobRecord> = Vec::new();
        for m in &sweep.members {
            if records.iter().all(|r| r.id != *m) {
                let mut r = self.store.get(*m).ok()??;
                if let Some((p, _)) = self.live_progress(r.id) {
                    r.progress = p;
                }
                records.push(r);
            }
        }
        let each = sweep
            .members
            .iter()
            .filter_map(|m| records.iter().find(|r| r.id == *m));
        Some(sweep_progress(sweep.progress.steps, each))
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

/// A sweep's progress: the steps of its members (succeeded: all theirs) out of `steps`.
fn sweep_progress<'a>(steps: usize, members: impl Iterator<Item = &'a JobRecord>) -> Progress {
    let done = members
        .map(|r| match r.status {
            JobStatus::Succeeded => r.progress.steps,
            _ => r.progress.step,
        })
        .sum::<usize>();
    Progress {
        step: done.min(steps),
        steps,
        last_residual: None,
    }
}

/// The problem of a sweep whose member `i` (job `r`) failed or was cancelled: the member's
/// status code (a scene's fault stays a 4xx), at the varied pointer the member's own error
/// names, else at the sweep's first varied pointer, with the member's index, values, job
/// and error in the detail.
fn member_failed(spec: &SweepSpec, i: usize, r: &JobRecord) -> Problem {
    let m = &spec.members[i];
    let (status, what) = match r.error.as_ref().filter(|_| r.status == JobStatus::Failed) {
        Some(e) => (
            e["status"]
                .as_u64()
                .and_then(|s| StatusCode::from_u16(s as u16).ok())
                .unwrap_or(StatusCode::INTERNAL_SERVER_ERROR),
            format!(
                "failed: {}: {}",
                e["title"].as_str().unwrap_or("error"),
                e["detail"].as_str().unwrap_or("")
            ),
        ),
        None => (StatusCode::CONFLICT, "was cancelled".to_string()),
    };
    let named = r
        .error
        .as_ref()
        .and_then(|e| e["errors"][0]["pointer"].as_str());
    let pointer = spec
        .vary
        .iter()
        .find(|(p, _)| named.is_some_and(|n| n == p || n.starts_with(&format!("{p}/"))))
        .unwrap_or(&spec.vary[0])
        .0
        .clone();
    Problem::field(
        status,
        "a member of the sweep failed",
        &format!("/sweep/vary/{}", study::sweep::escape(&pointer)),
        format!("member {i} ({}), job {}, {what}", spec.describe(m), r.id),
    )
    .with_type("/problems/sweep-member")
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
