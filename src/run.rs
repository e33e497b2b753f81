//! One job from a validated problem to its summary: set-up, the time loop, and a callback
//! per step (progress, cancellation, storing fields). Used by the CLI and the service.

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
pub fn run(
    problem: Problem,
    settings: SolverSettings,
    mut each: impl FnMut(&Simulation, &StepReport) -> ControlFlow<()>,
) -> Result<Summary, RunError> {
    let mut sim = Simulation::new(problem, settings)?;
    let start = Instant::now();
    let mut reports = Vec::with_capacity(sim.problem.steps);
    while !sim.finished() {
        let r = sim.step()?;
        if each(&sim, &r).is_break() {
            return Err(RunError::Cancelled(r.n));
        }
        reports.push(r);
    }
    Ok(Summary::new(&sim, reports, start.elapsed().as_secs_f64()))
}

/// Runs `problem` to t = T and returns the simulation in its final state (no callback, no
/// summary): what convergence studies need.
pub fn run_to_end(problem: Problem, settings: SolverSettings) -> Result<Simulation, RunError> {
    let mut sim = Simulation::new(problem, settings)?;
    while !sim.finished() {
        sim.step()?;
    }
    Ok(sim)
}
