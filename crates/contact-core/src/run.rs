//! One job from a validated problem to its summary: set-up, the time loop, and a callback
//! per step (progress, cancellation, storing fields). Used by the CLI and the service.

use crate::estimate::ErrorEstimator;
use crate::output::Summary;
use crate::problem::Problem;
use crate::solve::stepper::{Simulation, StepReport};
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

/// Runs `problem` to t = T. `each` sees the simulation after every step (fields of stored
/// steps are available from `sim.fields()`); returning `ControlFlow::Break` cancels.
/// D is the problem's dimension ([`Problem::dim`]).
pub fn run<const D: usize>(
    problem: Problem,
    settings: SolverSettings,
    mut each: impl FnMut(&Simulation<D>, &StepReport) -> ControlFlow<()>,
) -> Result<Summary, RunError> {
    let mut sim = Simulation::<D>::new(problem, settings)?;
    let mut estimator = match sim.problem.error_estimate {
        true => Some(ErrorEstimator::new(&sim, settings)?),
        false => None,
    };
    let start = Instant::now();
    let mut reports = Vec::with_capacity(sim.problem.steps);
    while !sim.finished() {
        let r = sim.step()?;
        if let Some(e) = estimator.as_mut() {
            e.after_step(&sim, sim.problem.output.stores(r.n, sim.problem.steps))?;
        }
        if each(&sim, &r).is_break() {
            return Err(RunError::Cancelled(r.n));
        }
        reports.push(r);
    }
    let mut summary = Summary::new(&sim, reports, start.elapsed().as_secs_f64());
    summary.error_estimate = estimator.map(ErrorEstimator::finish);
    Ok(summary)
}

/// Runs `problem` to t = T and returns the simulation in its final state (no callback, no
/// summary): what convergence studies need.
pub fn run_to_end<const D: usize>(
    problem: Problem,
    settings: SolverSettings,
) -> Result<Simulation<D>, RunError> {
    let mut sim = Simulation::<D>::new(problem, settings)?;
    while !sim.finished() {
        sim.step()?;
    }
    Ok(sim)
}
