//! A simulation job: the core's run driver ([`contact_core::run`]) with this worker's hooks
//! (cancel, shutdown, stored steps, progress, checkpoints), resumed from its last checkpoint.

use super::{failure, solve_problem, write_failure, Outcome, Runtime, CHECKPOINT_EVERY};
use super::{step_file, ESTIMATES_FILE, REPORTS_FILE, STATE_FILE, SUMMARY_FILE};
use crate::problem::Problem;
use crate::store::{JobRecord, Progress, StoreError};
use contact_core::estimate::EstimateRow;
use contact_core::output::stored::{decode_state, encode_state, encode_step};
use contact_core::run::{Hooks, Run};
use contact_core::scene;
use contact_core::solve::stepper::{Simulation, State, StepReport};
use contact_core::solve::SolverSettings;
use std::ops::ControlFlow;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;
use uuid::Uuid;

impl Runtime {
    pub(super) fn execute(
        &self,
        job: &JobRecord,
        worker: &str,
        cancel: &AtomicBool,
    ) -> Result<Outcome, Problem> {
        if let Some(mesh) = crate::meshes::mesh_ref(&job.scene) {
            // The mesh is read through the store: wait for a shared database that is
            // restarting rather than fail the job for it.
            self.with_store_retry(|| self.store.get_mesh(&mesh))
                .map_err(|e| failure("cannot read the job's mesh", &e.to_string()))?;
        }
        let problem = scene::validate_with(&super::scene_of(&job.scene), &*self.meshes)
            .map_err(|e| failure("stored scene no longer validates", &e.to_string()))?;
        match problem.dim() {
            2 => self.execute_in::<2>(job, worker, cancel, problem),
            _ => self.execute_in::<3>(job, worker, cancel, problem),
        }
    }

    /// [`Self::execute`] of a validated problem of dimension D: the core's run driver with
    /// this worker's [`JobHooks`], resumed from the job's last checkpoint, if any.
    fn execute_in<const D: usize>(
        &self,
        job: &JobRecord,
        worker: &str,
        cancel: &AtomicBool,
        problem: contact_core::problem::Problem,
    ) -> Result<Outcome, Problem> {
        let id = job.id;
        let settings = SolverSettings {
            memory_limit: self.config.max_job_memory,
            threads: self.config.threads_per_job,
            ..SolverSettings::default()
        };
        let mut run = Run::<D>::new(problem, settings).map_err(|e| solve_problem(&e))?;
        if let Some((state, reports, rows)) = self
            .resume(id, run.sim())
            .map_err(|e| failure("checkpoint unreadable", &e))?
        {
            let step = state.step;
            run.resume(state, reports, rows)
                .map_err(|e| solve_problem(&e))?;
            tracing::info!(
                "job {id} resumed from step {step} (attempt {})",
                job.attempt
            );
        } else if let Some(parent) = super::parent_id(&job.scene) {
            let (state, reports) = self.parent_start(parent, run.sim())?;
            let step = state.step;
            run.resume(state, reports, Vec::new())
                .map_err(|e| solve_problem(&e))?;
            tracing::info!("job {id} continues job {parent} from its step {step}");
        }
        let mut hooks = JobHooks {
            rt: self,
            id,
            worker,
            cancel,
            last_checkpoint: Instant::now(),
        };
        match run.drive(&mut hooks).map_err(|e| solve_problem(&e))? {
            ControlFlow::Break(stop) => return stop,
            ControlFlow::Continue(()) => {}
        }
        // A worker that was paused (not killed) past its lease may find the job taken over
        // by another: it must not complete it a second time.
        if let Some(stop) = self.lost(id, worker) {
            return Ok(stop);
        }
        // The last state first: a summary present means the job's results are complete.
        let last = encode_state(&run.sim().checkpoint_state());
        self.results
            .write_atomic(id, STATE_FILE, &last)
            .map_err(|e| write_failure(&e))?;
        let mut summary = serde_json::to_value(run.summary()).expect("summary serialises");
        if let Some(link) = super::parent_of(&job.scene) {
            summary[super::CONTINUED_FROM] = link.clone();
        }
        let text = serde_json::to_vec_pretty(&summary).expect("summary serialises");
        self.results
            .write_atomic(id, SUMMARY_FILE, &text)
            .map_err(|e| write_failure(&e))?;
        Ok(Outcome::Succeeded)
    }

    /// [`Self::save_checkpoint`]; a store that is unreachable just now (shared database
    /// restarting) skips this checkpoint — the job goes on and the next one is tried a
    /// second later — while any other failure fails the job.
    fn checkpoint<const D: usize>(&self, id: Uuid, run: &Run<D>) -> Result<(), Problem> {
        match self.save_checkpoint(id, run) {
            Ok(()) => Ok(()),
            Err(StoreError::Unavailable(e)) => {
                tracing::warn!("checkpoint of {id} skipped, store unavailable: {e}");
                Ok(())
            }
            Err(StoreError::Io(e)) => Err(write_failure(&e)),
            Err(e) => Err(failure("checkpoint failed", &e.to_string())),
        }
    }

    /// Saves the per-step reports, then (u, ζ, step) in the store. A crash between the two
    /// leaves more reports than the checkpoint step; `resume` truncates them.
    fn save_checkpoint<const D: usize>(&self, id: Uuid, run: &Run<D>) -> Result<(), StoreError> {
        let sim = run.sim();
        let bytes = serde_json::to_vec(run.reports()).expect("reports serialise");
        self.results.write_atomic(id, REPORTS_FILE, &bytes)?;
        if let Some(e) = run.estimator() {
            let bytes = serde_json::to_vec(&e.rows).expect("estimates serialise");
            self.results.write_atomic(id, ESTIMATES_FILE, &bytes)?;
        }
        self.store
            .checkpoint(id, sim.state.step, &encode_state(&sim.checkpoint_state()))?;
        self.store.set_progress(
            id,
            Progress {
                step: sim.state.step,
                steps: sim.problem.steps,
                last_residual: None,
            },
        )
    }

    /// The last checkpoint of a run of `sim`'s shape, if any: the state, and the reports and
    /// error-estimate rows up to it.
    fn resume<const D: usize>(
        &self,
        id: Uuid,
        sim: &Simulation<D>,
    ) -> Result<Option<Resumed>, String> {
        let Some((step, bytes)) = self
            .with_store_retry(|| self.store.load_checkpoint(id))
            .map_err(|e| e.to_string())?
        else {
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
        let mut rows: Vec<EstimateRow> = match self
            .results
            .read(id, ESTIMATES_FILE)
            .map_err(|e| e.to_string())?
        {
            Some(b) => serde_json::from_slice(&b).map_err(|e| e.to_string())?,
            None => Vec::new(),
        };
        rows.retain(|r| r.n <= step);
        Ok(Some((state, reports, rows)))
    }
}

impl Runtime {
    /// Where a continuation starts: its parent's last state and the reports of the parent's
    /// steps (from its summary), checked against the child's shape. A parent deleted
    /// meanwhile fails the job at `/continue/job`.
    fn parent_start<const D: usize>(
        &self,
        parent: Uuid,
        sim: &Simulation<D>,
    ) -> Result<(State, Vec<StepReport>), Problem> {
        let gone = || {
            Problem::invalid_field(
                "/continue/job",
                format!("job {parent}, the continued job, was deleted before this one ran"),
            )
        };
        let read = |name: &str| {
            self.results
                .read(parent, name)
                .map_err(|e| failure("cannot read the parent's results", &e.to_string()))?
                .ok_or_else(gone)
        };
        let state = decode_state(&read(STATE_FILE)?)
            .map_err(|e| failure("the parent's state is unreadable", &e.to_string()))?;
        let summary: serde_json::Value = serde_json::from_slice(&read(SUMMARY_FILE)?)
            .map_err(|e| failure("the parent's summary is unreadable", &e.to_string()))?;
        let reports: Vec<StepReport> = serde_json::from_value(summary["steps"].clone())
            .map_err(|e| failure("the parent's summary is unreadable", &e.to_string()))?;
        if state.step != reports.len()
            || state.step >= sim.problem.steps
            || state.u.len() != sim.state.u.len()
            || state.zeta.len() != sim.state.zeta.len()
        {
            return Err(failure(
                "the parent's state does not fit",
                &format!(
                    "state after step {} of a body of {} values; this run has {} steps, {} values",
                    state.step,
                    state.u.len(),
                    sim.problem.steps,
                    sim.state.u.len()
                ),
            ));
        }
        Ok((state, reports))
    }
}

/// A checkpoint's state with the per-step reports and error-estimate rows up to it.
type Resumed = (State, Vec<StepReport>, Vec<EstimateRow>);

/// A simulation job's hooks on the core's run driver: cancel and shutdown before each step
/// (a checkpoint first, so the job resumes there), the stored steps written atomically,
/// progress to subscribers after each step and a checkpoint about once a second (after
/// making sure the job is still this worker's).
struct JobHooks<'a> {
    rt: &'a Runtime,
    id: Uuid,
    worker: &'a str,
    cancel: &'a AtomicBool,
    last_checkpoint: Instant,
}

impl<const D: usize> Hooks<D> for JobHooks<'_> {
    type Stop = Result<Outcome, Problem>;

    fn before_step(&mut self, run: &Run<D>) -> ControlFlow<Self::Stop> {
        if self.cancel.load(Ordering::SeqCst) {
            return ControlFlow::Break(Ok(Outcome::Cancelled));
        }
        if self.rt.shutdown.load(Ordering::SeqCst) {
            if let Some(stop) = self.rt.lost(self.id, self.worker) {
                return ControlFlow::Break(Ok(stop));
            }
            return ControlFlow::Break(
                self.rt
                    .checkpoint(self.id, run)
                    .map(|()| Outcome::Interrupted),
            );
        }
        ControlFlow::Continue(())
    }

    fn stored_step(&mut self, run: &Run<D>, r: &StepReport) -> ControlFlow<Self::Stop> {
        let fields = encode_step(&run.sim().fields());
        match self
            .rt
            .results
            .write_atomic(self.id, &step_file(r.n), &fields)
        {
            Ok(()) => ControlFlow::Continue(()),
            Err(e) => ControlFlow::Break(Err(write_failure(&e))),
        }
    }

    fn after_step(&mut self, run: &Run<D>, r: &StepReport) -> ControlFlow<Self::Stop> {
        let residual = r
            .velocity
            .residual
            .max(r.damage.map_or(0.0, |d| d.residual));
        self.rt.steps_done.fetch_add(1, Ordering::Relaxed);
        self.rt.running_progress(
            self.id,
            Progress {
                step: r.n,
                steps: run.sim().problem.steps,
                last_residual: Some(residual),
            },
        );
        if self.last_checkpoint.elapsed() >= CHECKPOINT_EVERY && !run.finished() {
            self.last_checkpoint = Instant::now();
            // Ownership first: a worker that lost the job must not overwrite the checkpoint
            // of the worker that holds it now.
            if let Some(stop) = self.rt.lost(self.id, self.worker) {
                return ControlFlow::Break(Ok(stop));
            }
            if let Err(p) = self.rt.checkpoint(self.id, run) {
                return ControlFlow::Break(Err(p));
            }
        }
        ControlFlow::Continue(())
    }
}
