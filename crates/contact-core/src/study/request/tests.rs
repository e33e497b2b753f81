use super::*;
use crate::memory;
use crate::run::RunError;
use crate::scene::Bundled;
use crate::solve::SolveError;
use serde_json::json;

fn read(doc: Value) -> Request {
    parse(&doc, "/study", &Bundled).unwrap().0
}

/// The preset `name` with `solver.linear` = "direct".
fn direct(name: &str) -> Value {
    let mut scene = crate::scene::presets::get(name).unwrap();
    scene["solver"] = json!({"linear": "direct"});
    scene
}

/// The case: box-exp3 with the direct solver demanded, a ladder at 1/4 and 1/8 with
/// its reference at 1/24.
fn direct_box_ladder() -> Request {
    read(json!({
        "scene": direct("box-exp3"),
        "h": ["1/4", "1/8"], "k": "1/8",
        "reference": {"h": "1/24", "k": "1/8"}
    }))
}

fn memory_limit(bytes: u64) -> Limits {
    Limits {
        max_memory: Some(bytes),
        ..Limits::default()
    }
}

#[test]
fn a_ladder_whose_reference_does_not_fit_the_memory_limit_is_refused_at_the_reference() {
    let req = direct_box_ladder();
    let Request::Ladder(plan) = &req else {
        panic!("a ladder")
    };
    let reference = crate::study::with(&plan.base, plan.reference);
    let predicted = memory::predict(&reference).direct;
    let e = req.admit(&memory_limit(predicted - 1)).unwrap_err();
    assert_eq!(e.pointer, "/study/reference/h");
    assert_eq!(e.limit, Limit::Memory);
    assert_eq!((e.needed, e.allowed), (predicted, predicted - 1));
    assert!(
        e.message
            .starts_with("the reference (h = 1/24, k = 1/8): the direct solver needs"),
        "{}",
        e.message
    );
    let ok = req.admit(&memory_limit(predicted)).unwrap();
    assert_eq!(
        ok.largest.memory_bytes, predicted,
        "the reference is the largest run"
    );
    assert_eq!(ok.steps, 3 * 8);
}

#[test]
fn a_ladder_is_refused_at_the_reference_for_nodes_and_for_its_steps_in_all() {
    let req = read(json!({
        "scene": "paper-convergence", "h": ["1/2", "1/4"], "k": "1/4",
        "reference": {"h": "1/16", "k": "1/4"}
    }));
    let e = req
        .admit(&Limits {
            max_nodes: Some(288),
            ..Limits::default()
        })
        .unwrap_err();
    assert_eq!((e.pointer.as_str(), e.needed), ("/study/reference/h", 289));
    let e = req
        .admit(&Limits {
            max_steps: Some(11),
            ..Limits::default()
        })
        .unwrap_err();
    assert_eq!((e.pointer.as_str(), e.needed), ("/study/reference/k", 12));
    assert!(req
        .admit(&Limits {
            max_nodes: Some(289),
            max_steps: Some(12),
            max_stored_bytes: Some(0),
            max_memory: None,
        })
        .is_ok());
}

#[test]
fn a_target_study_whose_pilots_do_not_fit_is_refused_at_its_scene() {
    let req = read(json!({
        "scene": direct("box-exp3"),
        "target": {"error": 0.1}
    }));
    let Request::Target { spec, .. } = &req else {
        panic!("a target study")
    };
    let finest = *spec.first_pilots().iter().max().unwrap();
    let predicted = memory::predict(&crate::study::with(&spec.base, finest)).direct;
    let e = req.admit(&memory_limit(predicted - 1)).unwrap_err();
    assert_eq!(
        (e.pointer.as_str(), e.limit),
        ("/study/scene", Limit::Memory)
    );
    assert!(
        e.message.starts_with("even the pilot runs"),
        "{}",
        e.message
    );
    let ok = req.admit(&memory_limit(predicted)).unwrap();
    assert_eq!(ok.largest.memory_bytes, predicted);
    assert_eq!(
        ok.steps,
        spec.first_pilots().iter().map(|l| l.1).sum::<usize>()
    );
}

#[test]
fn the_first_pilots_are_two_ladders_crossing_at_their_finest_level() {
    let Request::Target { spec, .. } = read(json!({
        "scene": "paper-convergence", "target": {"error": 0.1}
    })) else {
        panic!("a target study")
    };
    let n0 = spec.n0;
    let (s0, f) = (target::PILOT_STEPS, target::FIRST_PILOT_LEVELS);
    assert_eq!(f, 3, "the list below spells out three levels per ladder");
    let expected = [
        (n0, 4 * s0),
        (2 * n0, 4 * s0),
        (4 * n0, s0),
        (4 * n0, 2 * s0),
        (4 * n0, 4 * s0),
    ];
    assert_eq!(
        spec.first_pilots().into_iter().collect::<Vec<_>>(),
        expected
    );
    assert_eq!(spec.first_pilot_steps(), 15 * s0);
}

/// The worker applies the limit it was admitted under: executed without admission, a
/// ladder whose reference cannot fit fails in the reference's set-up, before any numeric
/// work, with the memory error (the limit is below the direct path's certain part).
#[test]
fn a_study_executed_under_a_limit_its_reference_cannot_fit_fails_with_the_memory_error() {
    let req = read(json!({
        "scene": direct("paper-convergence"),
        "h": ["1/2", "1/4"], "k": "1/4",
        "reference": {"h": "1/8", "k": "1/4"}
    }));
    let Request::Ladder(plan) = &req else {
        panic!("a ladder")
    };
    let reference = crate::study::with(&plan.base, plan.reference);
    let level = crate::study::with(&plan.base, plan.levels[1]);
    // Below the reference's certain bytes, above every level's whole prediction.
    let limit = memory::without_factors(&reference).direct - 1;
    assert!(memory::predict(&level).direct <= limit);
    let cache = ReferenceCache::new(0);
    let result = req.execute(Context {
        cache: &cache,
        threads: 1,
        settings: SolverSettings::default(),
        limits: memory_limit(limit),
        progress: &|_, _| ControlFlow::Continue(()),
        sink: &mut target::Discard,
    });
    assert!(
        matches!(
            result,
            Err(StudyError::Run(RunError::Solve(SolveError::Memory(_))))
        ),
        "{result:?}"
    );
    // Without the limit it runs.
    let result = req.execute(Context {
        cache: &cache,
        threads: 2,
        settings: SolverSettings::default(),
        limits: Limits::default(),
        progress: &|_, _| ControlFlow::Continue(()),
        sink: &mut target::Discard,
    });
    assert_eq!(result.unwrap().name(), plan.name);
}
