//! A target study's adaptive alternative (`"meshes": "auto"`;
//! docs/src/explanation/a-posteriori.md#adaptive-meshes-in-a-target-study).
//!
//! ```text
//! (h*, k*) = the walk's level that passed its (2h, 2k) check; its run estimated
//! η_u      = the spatial part of that run's relative estimate of w
//! cycles   = the adaptive study (crate::study::adapt) at k*, from the coarsest pilot mesh,
//!            until the spatial part of a cycle's estimate is ≤ η_u, with fewer nodes than h*'s
//! reached: the last cycle's mesh is the chosen run's (run again, its stored steps kept)
//! else:    the uniform run stays, and the result says why
//! ```
//!
//! Why the estimate and not the (2h, 2k) bar: an adaptive mesh has no (2h, 2k) companion. The
//! uniform level passed that check; an adaptive run of the same scene at the same k whose
//! estimate is no larger has an error no larger up to the estimator's efficiency band (the
//! indices measured drift by 1.26× over the l-bracket's adaptive cycles, 1.3–1.5× over two
//! to four uniform halvings of h and k).
//! Why the spatial part: both runs share k, so the time part is the same error in both and
//! refining cannot reduce it.

use super::chosen::run_chosen;
use super::result::MeshChoice;
use super::*;
use crate::mesh::AnyMesh;
use crate::study::adapt::{self, AdaptSpec, Row, Stop};

/// Cycles at most: from a coarse pilot mesh, Dörfler's θ = 1/2 adds about half the nodes a
/// cycle, so 24 cycles pass any uniform level within the node limits.
const MAX_CYCLES: usize = 24;

/// The adaptive alternative to the uniform run at `level` (whose summary, with its estimate,
/// is `uniform`): which is taken, and the adaptive run (summary and mesh) when that is. The
/// adaptive run's stored steps then replace the uniform run's in `sink`. `grow(n)` adds n
/// steps to the study's progress total; `tick` counts one step done (and cancels).
pub(super) fn consider<const D: usize>(
    planner: &Planner,
    level: (usize, usize),
    uniform: &Summary,
    sink: &mut dyn Sink,
    grow: &(dyn Fn(usize) + Sync),
    tick: &(dyn Fn() -> ControlFlow<()> + Sync),
) -> Result<(MeshChoice, Option<(Summary, AnyMesh)>), StudyError> {
    let spec = planner.spec;
    let eta_u = Row::new(uniform, 0, 0.0, None).space_estimate();
    let uniform_nodes = uniform.mesh.nodes;
    let cycles = AdaptSpec {
        name: spec.name.clone(),
        scene: spec.scene.clone(),
        base: planner.problem((spec.n0, level.1)),
        target: eta_u,
        theta: adapt::DEFAULT_THETA,
        max_nodes: Some(uniform_nodes.saturating_sub(1)),
        max_cycles: MAX_CYCLES,
        uniform: false,
        reference: None,
        spatial: true,
    };
    let progress = |_: usize, _: usize| {
        grow(1);
        tick()
    };
    let r = adapt::run(
        &cycles,
        planner.exec,
        planner.limits,
        &progress,
        &mut Discard,
    )?;
    let last = r
        .cycles
        .last()
        .expect("an adaptive study runs its first cycle");
    let mut choice = MeshChoice {
        policy: Meshes::Auto,
        taken: "uniform",
        reason: String::new(),
        uniform_estimate: Some(eta_u),
        uniform_nodes: Some(uniform_nodes),
        cycles: r.cycles.clone(),
        stopped: Some(r.stopped),
    };
    if !r.reached {
        let at = format!(
            "after {} adaptive cycles the spatial estimate is {:.3e} > the uniform run's {:.3e}",
            r.cycles.len(),
            last.space_estimate(),
            eta_u
        );
        choice.reason = match r.stopped {
            Stop::MaxNodes => format!(
                "{at}, and the next mesh would have as many nodes as the uniform level's {uniform_nodes}"
            ),
            Stop::NothingToRefine => "every indicator is zero: the uniform mesh is as good as any".into(),
            Stop::Memory => format!("{at}, and the next mesh would not fit the memory limit"),
            Stop::MaxCycles | Stop::TimeStep | Stop::Target => format!("{at} ({MAX_CYCLES} cycles at most)"),
        };
        return Ok((choice, None));
    }
    sink.restart().map_err(StudyError::Output)?;
    grow(level.1);
    let problem = adapt::on_any_mesh(&cycles.base, r.final_mesh.clone(), "adaptive mesh".into());
    let (_, summary) = run_chosen::<D>(&problem, planner.exec, false, sink, tick)?;
    choice.taken = "adaptive";
    choice.reason = format!(
        "cycle {} has {} nodes, {:.2} × the uniform level's {}, and a spatial estimate {:.3e} ≤ the uniform run's {:.3e}",
        r.cycles.len() - 1,
        last.nodes,
        last.nodes as f64 / uniform_nodes as f64,
        uniform_nodes,
        last.space_estimate(),
        eta_u
    );
    Ok((choice, Some((summary, r.final_mesh))))
}
