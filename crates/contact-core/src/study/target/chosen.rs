//! A target study's chosen run: its stored steps to the study's [`Sink`], its solver figures,
//! its summary and its fields at T.

use super::*;
use crate::solve::SolverSettings;

/// The chosen run: its stored steps to `sink`, its summary, and its fields at T.
pub(super) fn run_chosen<const D: usize>(
    problem: &Problem,
    exec: Execution,
    keep_u: bool,
    sink: &mut dyn Sink,
    tick: &(dyn Fn() -> ControlFlow<()> + Sync),
) -> Result<(LevelRun<D>, Summary), StudyError> {
    let start = Instant::now();
    let settings = SolverSettings {
        threads: exec.threads,
        ..exec.settings
    };
    let mut run = Run::<D>::new(problem.clone(), settings).map_err(RunError::from)?;
    let mut hooks = Chosen {
        stats: StatsAccumulator::new(exec.settings),
        sink,
        tick,
    };
    match run.drive(&mut hooks).map_err(RunError::from)? {
        ControlFlow::Break(Some(e)) => return Err(StudyError::Output(e)),
        ControlFlow::Break(None) => return Err(StudyError::Cancelled),
        ControlFlow::Continue(()) => {}
    }
    let stats = hooks.stats.finish();
    let sim = run.sim();
    let snapshot = Snapshot {
        step: problem.steps,
        w: sim.w.clone(),
        zeta: sim.state.zeta.clone(),
        u: if keep_u {
            sim.state.u.clone()
        } else {
            Vec::new()
        },
    };
    let unknowns = sim.dofs.n_free();
    let seconds = start.elapsed().as_secs_f64();
    let mesh = sim.mesh.clone();
    let summary = run.summary();
    let run = LevelRun {
        unknowns,
        steps: problem.steps,
        seconds,
        stats,
        snapshots: vec![snapshot],
        mesh,
    };
    Ok((run, summary))
}

/// The chosen run's hooks: its stored steps to the sink (`Break(Some)`: a write failed), its
/// solver figures, the study's tick (`Break(None)`: cancelled).
struct Chosen<'a> {
    stats: StatsAccumulator,
    sink: &'a mut dyn Sink,
    tick: &'a (dyn Fn() -> ControlFlow<()> + Sync),
}

impl<const D: usize> Hooks<D> for Chosen<'_> {
    type Stop = Option<std::io::Error>;

    fn stored_step(&mut self, run: &Run<D>, _: &StepReport) -> ControlFlow<Self::Stop> {
        match self.sink.step(&run.sim().fields()) {
            Ok(()) => ControlFlow::Continue(()),
            Err(e) => ControlFlow::Break(Some(e)),
        }
    }

    fn after_step(&mut self, _: &Run<D>, r: &StepReport) -> ControlFlow<Self::Stop> {
        self.stats.add(r);
        match (self.tick)() {
            ControlFlow::Break(()) => ControlFlow::Break(None),
            ControlFlow::Continue(()) => ControlFlow::Continue(()),
        }
    }
}
