//! One run of a study: a resolution (h, k) of the scene taken to t = T, keeping w and ζ at
//! the time nodes the study compares, and the solver figures of the run.

use crate::linalg::par::Threads;
use crate::mesh::SharedMesh;
use crate::problem::Problem;
use crate::run::{Hooks, Run, RunError};
use crate::solve::stepper::{Prepared, StepReport};
use crate::solve::SolverSettings;
use serde::Serialize;
use std::collections::BTreeSet;
use std::ops::ControlFlow;
use std::sync::Mutex;
use std::time::Instant;

/// What to run and which step indices n (t_n = n k) to keep.
pub struct Work {
    pub problem: Problem,
    pub keep: BTreeSet<usize>,
    /// The run is a study's reference (its norms are computed as soon as it ends).
    pub is_reference: bool,
    /// Runs with equal keys have the same mesh and physics and share one [`Prepared`]
    /// set-up (the factored velocity operator does not depend on k).
    pub share: Option<(String, usize)>,
    /// Also keep the displacement u at the kept steps (target studies of u).
    pub keep_u: bool,
}

impl Work {
    /// Relative cost used to schedule the largest runs first: nodes × steps.
    pub fn cost(&self) -> usize {
        self.problem.n_nodes() * self.problem.steps
    }
}

/// w_n (interleaved components per node) and ζ_n at one kept step.
pub struct Snapshot {
    pub step: usize,
    pub w: Vec<f64>,
    pub zeta: Vec<f64>,
    /// Interleaved like w; empty unless the work asked for it ([`Work::keep_u`]).
    pub u: Vec<f64>,
}

/// Mean and maximum iterations of a sub-problem solver over a run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Iterations {
    pub mean: f64,
    pub max: usize,
}

/// Solver-side figures of one run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct RunStats {
    pub velocity_iterations: Iterations,
    /// None when the scene has no damage (no damage solve).
    pub damage_iterations: Option<Iterations>,
    /// Worst relative KKT residual of either sub-problem over all steps.
    pub worst_residual: f64,
    /// Steps in which a sub-problem solver came within 20 % of its iteration limit.
    pub steps_near_iteration_limit: usize,
}

pub struct LevelRun<const D: usize = 2> {
    pub mesh: SharedMesh<D>,
    pub unknowns: usize,
    pub steps: usize,
    /// Wall time of the whole run, set-up (assembly, factorisation) included.
    pub seconds: f64,
    pub stats: RunStats,
    /// In increasing step order.
    pub snapshots: Vec<Snapshot>,
}

impl<const D: usize> LevelRun<D> {
    pub fn snapshot_steps(&self) -> BTreeSet<usize> {
        self.snapshots.iter().map(|s| s.step).collect()
    }

    pub fn at(&self, step: usize) -> Option<&Snapshot> {
        self.snapshots
            .binary_search_by_key(&step, |s| s.step)
            .ok()
            .map(|i| &self.snapshots[i])
    }
}

/// Runs `work` to t = T; `tick` is called after every step (`Break` cancels). With `shared`,
/// the set-up is taken from (or, first, left in) that slot; a run that reuses it counts the
/// set-up's time in its own `seconds` all the same, so that work–precision figures are those
/// of standalone runs.
pub fn run_level<const D: usize>(
    work: &Work,
    settings: SolverSettings,
    tick: &(dyn Fn() -> ControlFlow<()> + Sync),
    shared: Option<&Mutex<Option<Prepared<D>>>>,
) -> Result<LevelRun<D>, super::StudyError> {
    let start = Instant::now();
    let mut reused_seconds = 0.0;
    let prepared = match shared {
        Some(slot) => {
            let mut slot = slot.lock().unwrap_or_else(|e| e.into_inner());
            match slot.as_ref() {
                Some(p) => {
                    reused_seconds = p.seconds;
                    p.clone()
                }
                None => {
                    let p = prepare::<D>(&work.problem, settings)?;
                    *slot = Some(p.clone());
                    p
                }
            }
        }
        None => prepare::<D>(&work.problem, settings)?,
    };
    let mut run =
        Run::from_prepared(work.problem.clone(), settings, prepared).map_err(RunError::from)?;
    let mut keep = Keep {
        work,
        tick,
        stats: StatsAccumulator::new(settings),
        snapshots: Vec::with_capacity(work.keep.len()),
    };
    if run.drive(&mut keep).map_err(RunError::from)?.is_break() {
        return Err(super::StudyError::Cancelled);
    }
    let sim = run.into_simulation();
    Ok(LevelRun {
        unknowns: sim.dofs.n_free(),
        steps: work.problem.steps,
        seconds: start.elapsed().as_secs_f64() + reused_seconds,
        stats: keep.stats.finish(),
        snapshots: keep.snapshots,
        mesh: sim.mesh,
    })
}

/// The set-up of a level's mesh within the memory limit, on the run's threads.
fn prepare<const D: usize>(
    problem: &Problem,
    settings: SolverSettings,
) -> Result<Prepared<D>, super::StudyError> {
    Threads::new(settings.threads)
        .install(|| Prepared::<D>::within(problem, settings.memory_limit))
        .map_err(|e| RunError::from(e).into())
}

/// A level's hooks: its solver figures, w and ζ (and u when asked) at the kept steps, and
/// the study's tick after every step (`Break`: cancelled).
struct Keep<'a> {
    work: &'a Work,
    tick: &'a (dyn Fn() -> ControlFlow<()> + Sync),
    stats: StatsAccumulator,
    snapshots: Vec<Snapshot>,
}

impl<const D: usize> Hooks<D> for Keep<'_> {
    type Stop = ();

    fn after_step(&mut self, run: &Run<D>, r: &StepReport) -> ControlFlow<()> {
        self.stats.add(r);
        if self.work.keep.contains(&r.n) {
            let sim = run.sim();
            self.snapshots.push(Snapshot {
                step: r.n,
                w: sim.w.clone(),
                zeta: sim.state.zeta.clone(),
                u: if self.work.keep_u {
                    sim.state.u.clone()
                } else {
                    Vec::new()
                },
            });
        }
        (self.tick)()
    }
}

/// Folds per-step solver reports into [`RunStats`].
pub struct StatsAccumulator {
    settings: SolverSettings,
    steps: usize,
    velocity_sum: usize,
    velocity_max: usize,
    damage_sum: usize,
    damage_max: usize,
    damage_steps: usize,
    worst_residual: f64,
    near_limit: usize,
}

impl StatsAccumulator {
    pub fn new(settings: SolverSettings) -> Self {
        StatsAccumulator {
            settings,
            steps: 0,
            velocity_sum: 0,
            velocity_max: 0,
            damage_sum: 0,
            damage_max: 0,
            damage_steps: 0,
            worst_residual: 0.0,
            near_limit: 0,
        }
    }

    pub fn add(&mut self, r: &StepReport) {
        self.steps += 1;
        self.velocity_sum += r.velocity.iterations;
        self.velocity_max = self.velocity_max.max(r.velocity.iterations);
        self.worst_residual = self.worst_residual.max(r.velocity.residual);
        let mut near = self.settings.near_iteration_limit(r.velocity.iterations);
        if let Some(d) = r.damage {
            self.damage_steps += 1;
            self.damage_sum += d.iterations;
            self.damage_max = self.damage_max.max(d.iterations);
            self.worst_residual = self.worst_residual.max(d.residual);
            near |= self.settings.near_iteration_limit(d.iterations);
        }
        self.near_limit += usize::from(near);
    }

    pub fn finish(&self) -> RunStats {
        let mean = |sum: usize, n: usize| if n == 0 { 0.0 } else { sum as f64 / n as f64 };
        RunStats {
            velocity_iterations: Iterations {
                mean: mean(self.velocity_sum, self.steps),
                max: self.velocity_max,
            },
            damage_iterations: (self.damage_steps > 0).then(|| Iterations {
                mean: mean(self.damage_sum, self.damage_steps),
                max: self.damage_max,
            }),
            worst_residual: self.worst_residual,
            steps_near_iteration_limit: self.near_limit,
        }
    }
}
