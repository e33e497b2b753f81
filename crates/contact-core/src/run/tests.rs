use super::*;
use crate::scene::{self, presets, Overrides};
use serde_json::json;
use std::path::{Path, PathBuf};

/// paper-exp3 at h = 1/4, N = 6 steps, storing every second step.
fn problem() -> Problem {
    let mut doc = presets::get("paper-exp3").unwrap();
    scene::apply_overrides(
        &mut doc,
        &Overrides {
            h: Some(json!("1/4")),
            k: Some(json!("1/6")),
            t_end: None,
        },
    );
    doc["output"] = json!({"every": 2, "fields": ["u", "zeta"]});
    scene::validate(&doc).unwrap()
}

/// Records which hook saw which step, and stops before `stop_before`.
struct Trace {
    events: Vec<(&'static str, usize)>,
    stop_before: Option<usize>,
}

impl Hooks<2> for Trace {
    type Stop = &'static str;
    fn before_step(&mut self, run: &Run<2>) -> ControlFlow<&'static str> {
        let next = run.sim().state.step + 1;
        self.events.push(("before", next));
        match self.stop_before == Some(next) {
            true => ControlFlow::Break("stopped"),
            false => ControlFlow::Continue(()),
        }
    }
    fn stored_step(&mut self, run: &Run<2>, report: &StepReport) -> ControlFlow<&'static str> {
        assert_eq!(
            run.sim().fields().n,
            report.n,
            "the sink sees the step just made"
        );
        assert_eq!(
            run.reports().len(),
            report.n - 1,
            "before its report is recorded"
        );
        self.events.push(("stored", report.n));
        ControlFlow::Continue(())
    }
    fn after_step(&mut self, run: &Run<2>, report: &StepReport) -> ControlFlow<&'static str> {
        assert_eq!(run.reports().last(), Some(report));
        self.events.push(("after", report.n));
        ControlFlow::Continue(())
    }
}

#[test]
fn hooks_see_every_step_in_order_and_the_sink_only_the_stored_ones() {
    let mut run = Run::<2>::new(problem(), SolverSettings::default()).unwrap();
    let mut trace = Trace {
        events: Vec::new(),
        stop_before: None,
    };
    assert_eq!(
        run.drive(&mut trace).unwrap(),
        ControlFlow::Continue(()),
        "no hook stopped it"
    );
    let mut expected = Vec::new();
    for n in 1..=6 {
        expected.push(("before", n));
        if n % 2 == 0 {
            expected.push(("stored", n));
        }
        expected.push(("after", n));
    }
    assert_eq!(trace.events, expected);
    assert!(run.finished());
    assert_eq!(run.reports().len(), 6);
}

/// A run stopped by a hook and driven on later makes the same steps, bit for bit, as one
/// driven straight through (what a cancel-free pause, e.g. a checkpoint, relies on).
#[test]
fn a_stopped_run_driven_on_equals_a_straight_run_bit_for_bit() {
    let straight = run::<2>(problem(), SolverSettings::default(), |_, _| {
        ControlFlow::Continue(())
    })
    .unwrap();
    let mut paused = Run::<2>::new(problem(), SolverSettings::default()).unwrap();
    let mut trace = Trace {
        events: Vec::new(),
        stop_before: Some(4),
    };
    assert_eq!(
        paused.drive(&mut trace).unwrap(),
        ControlFlow::Break("stopped")
    );
    assert_eq!(paused.reports().len(), 3, "steps 1-3 made, step 4 not");
    trace.stop_before = None;
    assert_eq!(paused.drive(&mut trace).unwrap(), ControlFlow::Continue(()));
    assert_eq!(paused.summary().steps, straight.steps);
}

/// A run resumed from a checkpoint state with its reports continues to the same steps.
#[test]
fn a_resumed_run_continues_from_the_checkpoint() {
    let mut first = Run::<2>::new(problem(), SolverSettings::default()).unwrap();
    let mut trace = Trace {
        events: Vec::new(),
        stop_before: Some(3),
    };
    let _ = first.drive(&mut trace).unwrap();
    let state = first.sim().checkpoint_state();
    let reports = first.reports().to_vec();
    let mut resumed = Run::<2>::new(problem(), SolverSettings::default()).unwrap();
    resumed.resume(state, reports, Vec::new()).unwrap();
    let ControlFlow::Continue(()) = resumed.drive(&mut ToEnd).unwrap();
    let straight = run_to_end::<2>(problem(), SolverSettings::default()).unwrap();
    assert_eq!(resumed.sim().state, straight.state);
    assert_eq!(resumed.reports().len(), 6);
}

/// A `Break` from `run`'s callback cancels at that step.
#[test]
fn runs_callback_cancels() {
    let r = run::<2>(problem(), SolverSettings::default(), |_, r| match r.n {
        2 => ControlFlow::Break(()),
        _ => ControlFlow::Continue(()),
    });
    assert!(matches!(r, Err(RunError::Cancelled(2))), "{r:?}");
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// A unit-test file: `tests.rs`, or a module its parent declares under `#[cfg(test)]`.
fn is_test_module(file: &Path) -> bool {
    let name = file.file_stem().unwrap().to_str().unwrap();
    if name == "tests" {
        return true;
    }
    let parent = file.parent().unwrap();
    [parent.join("mod.rs"), parent.with_extension("rs")]
        .iter()
        .filter_map(|p| std::fs::read_to_string(p).ok())
        .any(|text| text.contains(&format!("#[cfg(test)]\nmod {name};")))
}

/// [`Run::drive`] is the only time loop: outside unit tests and integration tests, no source
/// file of the workspace's libraries, binaries or benches calls a simulation's `step()`
/// but this module, and the error estimator, whose (2h, 2k) companions are stepped in
/// lock-step from the driver's own loop.
#[test]
fn the_driver_is_the_only_time_loop() {
    let core = Path::new(env!("CARGO_MANIFEST_DIR"));
    let root = core.join("../..");
    let mut files = Vec::new();
    for dir in [
        core.join("src"),
        core.join("benches"),
        root.join("src"),
        root.join("benches"),
    ] {
        rust_files(&dir, &mut files);
    }
    let allowed = [core.join("src/run/mod.rs"), core.join("src/estimate.rs")];
    let mut loops = Vec::new();
    for f in &files {
        if allowed.iter().any(|a| a == f) || is_test_module(f) {
            continue;
        }
        let text = std::fs::read_to_string(f).unwrap();
        for (i, line) in text.lines().enumerate() {
            let code = line.split("//").next().unwrap();
            if code.contains(".step()") {
                loops.push(format!("{}:{}: {}", f.display(), i + 1, line.trim()));
            }
        }
    }
    assert!(files.len() > 50, "the scan found the sources");
    assert!(
        loops.is_empty(),
        "a time loop outside contact_core::run (drive it with run::Run and hooks):\n{}",
        loops.join("\n")
    );
}

/// `preset` at h = k = 1/`level` (T shortened to `steps` steps), optionally on the multigrid
/// path and with a Tresca bound `g` low enough to make Γ3 slip.
fn threaded_case(
    preset: &str,
    level: usize,
    steps: usize,
    linear: &str,
    g: Option<f64>,
) -> Problem {
    let mut doc = presets::get(preset).unwrap();
    let frac = json!(format!("1/{level}"));
    let h = doc
        .get("mesh")
        .and_then(|m| m.get("h"))
        .is_some()
        .then(|| frac.clone());
    scene::apply_overrides(
        &mut doc,
        &Overrides {
            h,
            k: Some(frac),
            t_end: Some(json!(format!("{steps}/{level}"))),
        },
    );
    doc["solver"] = json!({ "linear": linear });
    if let Some(g) = g {
        doc["friction"] = json!({"law": "tresca", "g": g});
    }
    scene::validate(&doc).unwrap()
}

/// Every step's norms, counts and the final state of a run on `threads` threads, as bits.
fn fingerprint<const D: usize>(problem: &Problem, threads: usize) -> (Vec<[u64; 5]>, Vec<u64>) {
    let settings = SolverSettings {
        threads,
        ..SolverSettings::default()
    };
    let mut run = Run::<D>::new(problem.clone(), settings).unwrap();
    let ControlFlow::Continue(()) = run.drive(&mut ToEnd).unwrap();
    let steps = run
        .reports()
        .iter()
        .map(|r| {
            [
                r.w_v.to_bits(),
                r.u_v.to_bits(),
                r.zeta_l2.to_bits(),
                r.zeta_min.to_bits(),
                r.slip_nodes as u64,
            ]
        })
        .collect();
    let state = run.sim().state.u.iter().chain(&run.sim().state.zeta);
    (steps, state.map(|v| v.to_bits()).collect())
}

/// Threads change no bit of a run: 1, 2 and 4 threads, and the same count twice, give the
/// same norms at every step and the same final state, in 2D and 3D, on the direct and the
/// multigrid paths, on an imported mesh, sticking and slipping. (The unit-test build splits
/// vectors every 256 entries and products every 32 rows, so these small meshes run every
/// kernel's threaded path.)
#[test]
fn thread_counts_give_the_same_bits() {
    let cases: Vec<(&str, Problem)> = vec![
        (
            "paper-convergence, direct",
            threaded_case("paper-convergence", 8, 3, "direct", None),
        ),
        (
            "paper-convergence, multigrid, slip",
            threaded_case("paper-convergence", 8, 3, "multigrid", Some(0.05)),
        ),
        (
            "arch-on-support (curved Γ3, rotated frames), multigrid",
            threaded_case("arch-on-support", 8, 2, "multigrid", None),
        ),
        (
            "box-exp3, multigrid",
            threaded_case("box-exp3", 4, 2, "multigrid", None),
        ),
        (
            "box-exp3, multigrid, slip",
            threaded_case("box-exp3", 4, 2, "multigrid", Some(0.05)),
        ),
        (
            "standing-cylinder (gmsh), multigrid, slip",
            threaded_case("standing-cylinder", 16, 2, "multigrid", Some(0.2)),
        ),
    ];
    for (name, problem) in cases {
        let check = |threads: &[usize]| {
            let one = match problem.dim() {
                2 => fingerprint::<2>(&problem, 1),
                _ => fingerprint::<3>(&problem, 1),
            };
            for &t in threads {
                let other = match problem.dim() {
                    2 => fingerprint::<2>(&problem, t),
                    _ => fingerprint::<3>(&problem, t),
                };
                assert_eq!(one.0, other.0, "{name}: step norms, 1 against {t} threads");
                assert_eq!(one.1, other.1, "{name}: final state, 1 against {t} threads");
            }
            one
        };
        let (steps, _) = check(&[1, 2, 4]);
        if name.contains("slip") {
            assert!(
                steps.iter().any(|s| s[4] > 0),
                "{name}: the case is meant to slip"
            );
        }
    }
}
