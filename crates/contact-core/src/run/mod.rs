//! One run of a problem from its set-up to its summary: the only time loop of the workspace.
//! The command line, the service's worker, a study's levels and references, a target
//! study's chosen run, the stress suite and the bench all drive their runs through [`Run`],
//! and differ only in their [`Hooks`]:
//!
//! ```text
//! set-up (Simulation, with its error estimator when the scene asks for one)
//! for n = 1..N:
//!     hooks.before_step      cancel, lease, shutdown (a checkpoint first)
//!     Simulation::step       (3.10) ∥ (3.13), (3.12): the scheme's step n
//!     estimator.after_step   the (2h, 2k) companions advance in lock-step
//!     hooks.stored_step      the step sink, for the steps the scene's output stores
//!     hooks.after_step       progress, periodic checkpoints, per-step figures
//! summary (norms, solver statistics, the error estimate)
//! ```
//!
//! Every hook may stop the run with a value of its own ([`ControlFlow::Break`]), which
//! [`Run::drive`] returns.

use crate::estimate::{ErrorEstimator, EstimateRow};
use crate::linalg::par::Threads;
use crate::output::Summary;
use crate::problem::Problem;
use crate::solve::stepper::{Prepared, Simulation, State, StepReport};
use crate::solve::{SolveError, SolverSettings};
use std::ops::ControlFlow;
use std::time::Instant;

/// Why a run stopped early.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error(transparent)]
    Solve(#[from] SolveError),
    #[error("cancelled after step {0}")]
    Cancelled(usize),
}

/// What a caller does around each step of a [`Run`]; every method defaults to going on.
/// `Stop` is what a hook that ends the run early hands back through [`Run::drive`].
pub trait Hooks<const D: usize> {
    type Stop;

    /// Before each step (cancel, lease, shutdown).
    fn before_step(&mut self, _run: &Run<D>) -> ControlFlow<Self::Stop> {
        ControlFlow::Continue(())
    }

    /// After a step the scene's output stores: its fields are `run.sim().fields()`.
    fn stored_step(&mut self, _run: &Run<D>, _report: &StepReport) -> ControlFlow<Self::Stop> {
        ControlFlow::Continue(())
    }

    /// After every step, the report already in [`Run::reports`] (progress, checkpoints).
    fn after_step(&mut self, _run: &Run<D>, _report: &StepReport) -> ControlFlow<Self::Stop> {
        ControlFlow::Continue(())
    }
}

/// No hooks: the run goes to t = T.
pub struct ToEnd;

impl<const D: usize> Hooks<D> for ToEnd {
    type Stop = std::convert::Infallible;
}

/// A run in progress: the simulation, its error estimator (scenes with `error_estimate`),
/// the reports of the steps so far and the solve time.
pub struct Run<const D: usize> {
    sim: Simulation<D>,
    /// The pool its set-up and steps run in (`SolverSettings::threads`).
    threads: Threads,
    estimator: Option<ErrorEstimator<D>>,
    reports: Vec<StepReport>,
    /// When the first step was started (the summary's solve time counts from there).
    started: Option<Instant>,
    last_step_seconds: f64,
}

impl<const D: usize> Run<D> {
    /// Sets `problem` up (meshing, assembly, the solver backend) with its error estimator
    /// when the scene asks for one.
    pub fn new(problem: Problem, settings: SolverSettings) -> Result<Run<D>, SolveError> {
        let threads = Threads::new(settings.threads);
        let sim = threads.install(|| Simulation::new(problem, settings))?;
        Self::around(sim, threads)
    }

    /// [`Run::new`] on a set-up made before (shared by the runs of a study at one mesh).
    pub fn from_prepared(
        problem: Problem,
        settings: SolverSettings,
        prepared: Prepared<D>,
    ) -> Result<Run<D>, SolveError> {
        let threads = Threads::new(settings.threads);
        let sim = threads.install(|| Simulation::from_prepared(problem, settings, prepared))?;
        Self::around(sim, threads)
    }

    fn around(sim: Simulation<D>, threads: Threads) -> Result<Run<D>, SolveError> {
        let estimator = match sim.problem.error_estimate {
            true => Some(threads.install(|| ErrorEstimator::new(&sim, sim.settings))?),
            false => None,
        };
        Ok(Run {
            threads,
            reports: Vec::with_capacity(sim.problem.steps),
            sim,
            estimator,
            started: None,
            last_step_seconds: 0.0,
        })
    }

    /// Continues from a checkpoint: the state after its last step, the reports of the steps
    /// up to it and the error estimate's rows.
    pub fn resume(
        &mut self,
        state: State,
        reports: Vec<StepReport>,
        rows: Vec<EstimateRow>,
    ) -> Result<(), SolveError> {
        let step = state.step;
        self.sim.restore(state);
        self.reports = reports;
        if let Some(e) = self.estimator.as_mut() {
            e.catch_up(step, rows)?;
        }
        Ok(())
    }

    /// `f` of the simulation in the run's pool (measurements between steps with the run's
    /// threads, the bench's products).
    pub fn in_pool<R: Send>(&self, f: impl FnOnce(&Simulation<D>) -> R + Send) -> R {
        let sim = &self.sim;
        self.threads.install(|| f(sim))
    }

    /// [`Run::in_pool`] with the simulation mutable.
    pub fn in_pool_mut<R: Send>(&mut self, f: impl FnOnce(&mut Simulation<D>) -> R + Send) -> R {
        let sim = &mut self.sim;
        self.threads.install(|| f(sim))
    }

    pub fn sim(&self) -> &Simulation<D> {
        &self.sim
    }

    /// The simulation, for measurements between steps (the bench's substitutions).
    pub fn sim_mut(&mut self) -> &mut Simulation<D> {
        &mut self.sim
    }

    /// The reports of the steps so far, step 1 first.
    pub fn reports(&self) -> &[StepReport] {
        &self.reports
    }

    pub fn estimator(&self) -> Option<&ErrorEstimator<D>> {
        self.estimator.as_ref()
    }

    pub fn finished(&self) -> bool {
        self.sim.finished()
    }

    /// Wall time of the last step (the scheme's step and the estimator's companions).
    pub fn last_step_seconds(&self) -> f64 {
        self.last_step_seconds
    }

    /// Steps to t = T with `hooks` around every step; `Break(stop)` from a hook ends the
    /// run there and is returned (the run can be driven on later).
    pub fn drive<H: Hooks<D>>(
        &mut self,
        hooks: &mut H,
    ) -> Result<ControlFlow<H::Stop>, SolveError> {
        self.started.get_or_insert_with(Instant::now);
        while !self.sim.finished() {
            if let ControlFlow::Break(stop) = hooks.before_step(self) {
                return Ok(ControlFlow::Break(stop));
            }
            let start = Instant::now();
            let (sim, estimator) = (&mut self.sim, &mut self.estimator);
            let (report, stored) = self.threads.install(|| {
                let report = sim.step()?;
                let stored = sim.problem.output.stores(report.n, sim.problem.steps);
                if let Some(e) = estimator.as_mut() {
                    e.after_step(sim, stored)?;
                }
                Ok::<_, SolveError>((report, stored))
            })?;
            self.last_step_seconds = start.elapsed().as_secs_f64();
            if stored {
                if let ControlFlow::Break(stop) = hooks.stored_step(self, &report) {
                    return Ok(ControlFlow::Break(stop));
                }
            }
            self.reports.push(report.clone());
            if let ControlFlow::Break(stop) = hooks.after_step(self, &report) {
                return Ok(ControlFlow::Break(stop));
            }
        }
        Ok(ControlFlow::Continue(()))
    }

    /// The summary of the steps so far (the whole run once [`Run::finished`]).
    pub fn summary(self) -> Summary {
        let seconds = self.started.map_or(0.0, |s| s.elapsed().as_secs_f64());
        let mut summary = Summary::new(&self.sim, self.reports, seconds);
        summary.error_estimate = self.estimator.map(ErrorEstimator::finish);
        summary
    }

    /// The simulation in its final state (what a study keeps of a level: its mesh).
    pub fn into_simulation(self) -> Simulation<D> {
        self.sim
    }
}

/// Runs `problem` to t = T. `each` sees the simulation after every step (fields of stored
/// steps are available from `sim.fields()`); returning `ControlFlow::Break` cancels.
/// D is the problem's dimension ([`Problem::dim`]).
pub fn run<const D: usize>(
    problem: Problem,
    settings: SolverSettings,
    each: impl FnMut(&Simulation<D>, &StepReport) -> ControlFlow<()>,
) -> Result<Summary, RunError> {
    /// [`run`]'s callback as the after-step hook.
    struct Each<F>(F);
    impl<const D: usize, F: FnMut(&Simulation<D>, &StepReport) -> ControlFlow<()>> Hooks<D>
        for Each<F>
    {
        type Stop = usize;
        fn after_step(&mut self, run: &Run<D>, report: &StepReport) -> ControlFlow<usize> {
            match (self.0)(run.sim(), report) {
                ControlFlow::Break(()) => ControlFlow::Break(report.n),
                ControlFlow::Continue(()) => ControlFlow::Continue(()),
            }
        }
    }
    let mut r = Run::<D>::new(problem, settings)?;
    if let ControlFlow::Break(n) = r.drive(&mut Each(each))? {
        return Err(RunError::Cancelled(n));
    }
    Ok(r.summary())
}

/// Runs `problem` to t = T and returns the simulation in its final state (no callback, no
/// summary).
pub fn run_to_end<const D: usize>(
    problem: Problem,
    settings: SolverSettings,
) -> Result<Simulation<D>, RunError> {
    let mut r = Run::<D>::new(problem, settings)?;
    let ControlFlow::Continue(()) = r.drive(&mut ToEnd)?;
    Ok(r.into_simulation())
}

#[cfg(test)]
mod tests;
