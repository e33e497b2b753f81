//! Convergence studies: runs of one scene at several (h, k) compared with a finer reference
//! run on its nested mesh (docs/src/explanation/numerics.md#convergence-studies): the coarse P1 fields are interpolated onto the
//! reference mesh (exact, [`crate::fem::prolongation`]); relative errors
//! |w − w^hk|_V / |w|_V and |ζ − ζ^hk|_Z0 / |ζ|_Z0 at t = T and their maximum over the time
//! nodes common to both runs; observed orders between consecutive levels and a least-squares
//! order over the ladder.
//!
//! - [`spec`] reads a study document (`{"scene", "h", "k", "reference"}`) into a [`Plan`];
//! - [`levels`] runs one resolution and keeps its fields at the compared time nodes;
//! - [`reference`] holds reference runs shared between studies of the same scene;
//! - [`compare`] turns the runs into the error table ([`StudyResult`]);
//! - [`report_svg`] draws a study's two plots (error against h or k, error against time);
//! - [`presets`] are the paper's Tables 1–2;
//! - [`target`] runs a study with a target error instead of a ladder: pilot levels, the
//!   [`plan`] (error and cost models, the cheapest (h, k)), the chosen run and its check.

pub mod adapt;
pub mod compare;
pub mod format;
pub mod levels;
pub mod plan;
pub mod presets;
pub mod reference;
pub mod report_svg;
pub mod request;
mod schedule;
pub mod spec;
pub mod sweep;
pub mod target;

pub use compare::{StudyReference, StudyResult, StudyRow};
pub use reference::ReferenceCache;
pub use spec::{parse, parse_with, Plan, Vary};
pub use target::{is_target, TargetResult, TargetSpec};

use crate::problem::Problem;
use crate::run::RunError;
use crate::solve::SolverSettings;
use levels::{LevelRun, Work};
use reference::Reference;
pub(crate) use schedule::{run_all, Done};
use std::collections::BTreeSet;
use std::ops::ControlFlow;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// Snapshots of the reference kept for the time-maximum of the errors are capped at this
/// many bytes; above it the compared time nodes are thinned evenly (t = T is always kept).
pub const SNAPSHOT_BUDGET_BYTES: usize = 512 << 20;

#[derive(Debug, thiserror::Error)]
pub enum StudyError {
    #[error(transparent)]
    Run(#[from] RunError),
    #[error("level h = {h}, k = {k} is not nested in the reference (h = {ref_h}, k = {ref_k}): the reference mesh must refine it and its time grid must contain the level's")]
    NotNested {
        h: f64,
        k: f64,
        ref_h: f64,
        ref_k: f64,
    },
    #[error("cancelled")]
    Cancelled,
    /// A target study's target is out of reach of the limits (said before the expensive run).
    #[error("{message}")]
    Unreachable {
        message: String,
        /// The smallest predicted error reachable within the limits and its predicted time.
        best_error: Option<f64>,
        best_seconds: Option<f64>,
    },
    /// Writing the chosen run's stored steps failed.
    #[error("cannot write the chosen run's results: {0}")]
    Output(#[source] std::io::Error),
}

/// How a study is executed (not what it computes).
#[derive(Debug, Clone, Copy)]
pub struct Execution {
    pub settings: SolverSettings,
    /// The study's threads: runs computed at the same time (the reference and the levels
    /// are independent until they are compared) share them, at most one run per thread.
    pub threads: usize,
}

impl Default for Execution {
    fn default() -> Self {
        Execution {
            settings: SolverSettings::default(),
            threads: crate::linalg::par::Threads::available(),
        }
    }
}

/// Total time steps a study will compute (its progress scale) if the reference is not cached.
pub fn total_steps(plan: &Plan) -> usize {
    plan.levels.iter().map(|l| l.1).sum::<usize>() + plan.reference.1
}

/// Runs a study. `progress(done, total)` is called after every time step of every run, from
/// the computing threads; returning `Break` cancels the study.
pub fn run(
    plan: &Plan,
    cache: &ReferenceCache,
    exec: Execution,
    progress: &(dyn Fn(usize, usize) -> ControlFlow<()> + Sync),
) -> Result<StudyResult, StudyError> {
    let mut results = run_many(std::slice::from_ref(plan), cache, exec, progress)?;
    Ok(results.pop().expect("one study"))
}

/// Runs several studies as one schedule: the reference runs they share are computed once,
/// and all runs (references and levels of every study) share the threads, largest first, so
/// that the short levels fill the time a long reference takes.
pub fn run_many(
    plans: &[Plan],
    cache: &ReferenceCache,
    exec: Execution,
    progress: &(dyn Fn(usize, usize) -> ControlFlow<()> + Sync),
) -> Result<Vec<StudyResult>, StudyError> {
    let started = Instant::now();
    for plan in plans {
        check_nested(plan)?;
    }
    // The runs of one dimension share a schedule; a batch mixing 2D and 3D studies runs its
    // 3D schedule after the 2D one, on one progress scale.
    let (solid, plane): (Vec<usize>, Vec<usize>) =
        (0..plans.len()).partition(|&i| plans[i].base.dim() == 3);
    if solid.is_empty() {
        return run_many_in::<2>(plans, cache, exec, started, progress);
    }
    if plane.is_empty() {
        return run_many_in::<3>(plans, cache, exec, started, progress);
    }
    let pick = |idx: &[usize]| idx.iter().map(|&i| plans[i].clone()).collect::<Vec<_>>();
    let (plane_plans, solid_plans) = (pick(&plane), pick(&solid));
    let solid_total: usize = solid_plans.iter().map(total_steps).sum();
    let plane_done = AtomicUsize::new(0);
    let first = |done: usize, total: usize| {
        plane_done.store(total, Ordering::Relaxed);
        progress(done, total + solid_total)
    };
    let plane_results = run_many_in::<2>(&plane_plans, cache, exec, started, &first)?;
    let offset = plane_done.load(Ordering::Relaxed);
    let second = |done: usize, total: usize| progress(offset + done, offset + total);
    let solid_results = run_many_in::<3>(&solid_plans, cache, exec, started, &second)?;
    let mut results: Vec<Option<StudyResult>> = vec![None; plans.len()];
    for (i, r) in plane
        .into_iter()
        .chain(solid)
        .zip(plane_results.into_iter().chain(solid_results))
    {
        results[i] = Some(r);
    }
    Ok(results
        .into_iter()
        .map(|r| r.expect("every study ran"))
        .collect())
}

/// [`run_many`] of studies whose bodies have dimension D.
fn run_many_in<const D: usize>(
    plans: &[Plan],
    cache: &ReferenceCache,
    exec: Execution,
    started: Instant,
    progress: &(dyn Fn(usize, usize) -> ControlFlow<()> + Sync),
) -> Result<Vec<StudyResult>, StudyError> {
    let compared: Vec<BTreeSet<usize>> = plans.iter().map(compared_steps).collect();
    // One slot per distinct reference, locked in key order (no deadlock between concurrent
    // callers). Holding a slot while computing makes another study of the same reference
    // wait for this one instead of computing it twice.
    let mut groups: Vec<(String, Vec<usize>)> = Vec::new();
    for (i, plan) in plans.iter().enumerate() {
        let key = &plan.reference_key;
        match groups.iter_mut().find(|(k, _)| !k.is_empty() && k == key) {
            Some((_, members)) => members.push(i),
            None => groups.push((key.clone(), vec![i])),
        }
    }
    groups.sort_by(|a, b| a.0.cmp(&b.0));
    let slots: Vec<reference::Slot> = groups.iter().map(|(k, _)| cache.slot(k)).collect();
    let mut guards: Vec<_> = slots
        .iter()
        .map(|s| s.lock().unwrap_or_else(|e| e.into_inner()))
        .collect();
    let mut jobs: Vec<Work> = Vec::new();
    // Per group: the cached reference, or the index of the job computing it.
    let mut sources: Vec<Result<Arc<Reference<D>>, usize>> = Vec::new();
    for ((_, members), guard) in groups.iter().zip(&guards) {
        let mut keep: BTreeSet<usize> = BTreeSet::new();
        for &i in members {
            keep.extend(&compared[i]);
        }
        let cached = guard
            .as_ref()
            .and_then(|r| r.clone().downcast::<Reference<D>>().ok());
        match cached
            .as_ref()
            .filter(|r| keep.is_subset(&r.snapshot_steps()))
        {
            Some(r) => sources.push(Ok(r.clone())),
            None => {
                // The union with what an earlier study kept lets the new entry serve both.
                if let Some(old) = &cached {
                    keep.extend(old.snapshot_steps());
                }
                sources.push(Err(jobs.len()));
                let plan = &plans[members[0]];
                jobs.push(Work {
                    problem: with(&plan.base, plan.reference),
                    keep,
                    is_reference: true,
                    share: Some((plan.reference_key.clone(), plan.reference.0)),
                    keep_u: false,
                });
            }
        }
    }
    let mut level_jobs: Vec<Vec<usize>> = Vec::with_capacity(plans.len());
    for (plan, compared) in plans.iter().zip(&compared) {
        let mut idx = Vec::with_capacity(plan.levels.len());
        for &(n, steps) in &plan.levels {
            let ratio = plan.reference.1 / steps;
            let keep = compared
                .iter()
                .filter(|&&m| m % ratio == 0)
                .map(|&m| m / ratio)
                .collect();
            idx.push(jobs.len());
            jobs.push(Work {
                problem: with(&plan.base, (n, steps)),
                keep,
                is_reference: false,
                share: Some((plan.reference_key.clone(), n)),
                keep_u: false,
            });
        }
        level_jobs.push(idx);
    }
    // Only set-ups used by two runs or more are kept (each holds a factor in memory); an
    // empty key (an unshared reference) never identifies a physics.
    for j in 0..jobs.len() {
        let shared_by = |key: &(String, usize)| {
            jobs.iter()
                .filter(|o| o.share.as_ref() == Some(key))
                .count()
        };
        if jobs[j]
            .share
            .as_ref()
            .is_some_and(|k| k.0.is_empty() || shared_by(k) < 2)
        {
            jobs[j].share = None;
        }
    }
    let total = jobs.iter().map(|j| j.problem.steps).sum::<usize>();
    let mut done: Vec<Option<Done<D>>> = run_all(jobs, exec, total, progress)?
        .into_iter()
        .map(Some)
        .collect();
    let mut references: Vec<(Arc<Reference<D>>, bool)> = Vec::with_capacity(groups.len());
    for (source, guard) in sources.into_iter().zip(guards.iter_mut()) {
        references.push(match source {
            Ok(r) => (r, true),
            Err(j) => {
                let Some(Done::Reference(r)) = done[j].take() else {
                    unreachable!("job {j} computed a reference")
                };
                let r = Arc::new(r);
                **guard = Some(r.clone());
                (r, false)
            }
        });
    }
    drop(guards);
    let mut results = Vec::with_capacity(plans.len());
    for (i, plan) in plans.iter().enumerate() {
        let g = groups
            .iter()
            .position(|(_, m)| m.contains(&i))
            .expect("grouped");
        let (reference, cached) = &references[g];
        // Later studies of a group reuse the reference the first one computed.
        let cached = *cached || groups[g].1[0] != i;
        let runs: Vec<LevelRun<D>> = level_jobs[i]
            .iter()
            .map(|&j| match done[j].take() {
                Some(Done::Level(r)) => r,
                _ => unreachable!("job {j} ran a level"),
            })
            .collect();
        results.push(compare::tabulate(
            plan,
            reference,
            cached,
            &runs,
            &compared[i],
            exec.threads,
            started.elapsed().as_secs_f64(),
        ));
    }
    Ok(results)
}

fn check_nested(plan: &Plan) -> Result<(), StudyError> {
    let (ref_n, ref_steps) = plan.reference;
    for &(n, steps) in &plan.levels {
        if n == 0 || steps == 0 || ref_n % n != 0 || ref_steps % steps != 0 {
            return Err(StudyError::NotNested {
                h: 1.0 / n as f64,
                k: plan.base.t_end / steps as f64,
                ref_h: 1.0 / ref_n as f64,
                ref_k: plan.base.t_end / ref_steps as f64,
            });
        }
    }
    Ok(())
}

/// [`with`] for callers outside the crate (a level's problem, e.g. to check limits).
pub fn with_resolution(base: &Problem, level: (usize, usize)) -> Problem {
    with(base, level)
}

/// The problem at one level: n cells per unit length on a rectangle; on a given mesh,
/// n = 2^refine ([`spec::resolution`]).
pub(crate) fn with(base: &Problem, (n, steps): (usize, usize)) -> Problem {
    let body = base.body.as_ref().map(|b| {
        std::sync::Arc::new(crate::problem::Body {
            refine: n.trailing_zeros() as usize,
            ..(**b).clone()
        })
    });
    Problem {
        body,
        cells_per_unit: if base.body.is_some() { 0 } else { n },
        steps,
        ..base.clone()
    }
}

/// The reference steps at which errors are compared: every node of the reference grid that
/// is also a node of some level, thinned evenly to fit [`SNAPSHOT_BUDGET_BYTES`].
fn compared_steps(plan: &Plan) -> BTreeSet<usize> {
    let (ref_n, ref_steps) = plan.reference;
    let mut all = BTreeSet::new();
    for &(_, steps) in &plan.levels {
        let ratio = ref_steps / steps.max(1);
        all.extend((1..=steps).map(|m| m * ratio));
    }
    // ζ per node and the strain's components per cell (see reference::Reference); a given
    // mesh has about two triangles, or about six tetrahedra, per node.
    let reference = with(&plan.base, (ref_n, ref_steps));
    let per_cell = reference::sym_len(reference.dim());
    let per_snapshot = match (&reference.body, reference.depth_cells()) {
        (None, None) => {
            let (nx, ny) = reference.cells();
            ((nx + 1) * (ny + 1) + 2 * nx * ny * per_cell) * 8
        }
        (None, Some(nz)) => {
            let (nx, ny) = reference.cells();
            ((nx + 1) * (ny + 1) * (nz + 1) + 6 * nx * ny * nz * per_cell) * 8
        }
        (Some(_), _) => {
            let cells_per_node = if reference.dim() == 3 { 6 } else { 2 };
            (1 + cells_per_node * per_cell) * reference.n_nodes() * 8
        }
    };
    let fit = (SNAPSHOT_BUDGET_BYTES / per_snapshot.max(1)).max(1);
    if all.len() <= fit {
        return all;
    }
    let stride = all.len().div_ceil(fit);
    let v: Vec<usize> = all.into_iter().collect();
    let last = *v.last().expect("non-empty");
    let mut thinned: BTreeSet<usize> = v.into_iter().rev().step_by(stride).collect();
    thinned.insert(last);
    thinned
}

/// Runs every `(cells_per_unit, steps)` level of `base` and the reference, without a shared
/// cache or progress reporting (library callers and tests).
pub fn run_ladder(
    base: &Problem,
    levels: &[(usize, usize)],
    reference: (usize, usize),
) -> Result<StudyResult, StudyError> {
    let vary = if levels.windows(2).all(|w| w[0].1 == w[1].1) {
        Vary::H
    } else if levels.windows(2).all(|w| w[0].0 == w[1].0) {
        Vary::K
    } else {
        Vary::Both
    };
    let plan = Plan {
        name: base.name.clone(),
        base: base.clone(),
        levels: levels.to_vec(),
        reference,
        vary,
        reference_key: String::new(),
        level_pointers: (0..levels.len())
            .map(|i| [format!("/h/{i}"), format!("/k/{i}")])
            .collect(),
        reference_pointers: ["/reference/h".into(), "/reference/k".into()],
    };
    run(
        &plan,
        &ReferenceCache::new(0),
        Execution::default(),
        &|_, _| ControlFlow::Continue(()),
    )
}
