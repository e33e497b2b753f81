use super::*;
use crate::scene::Bundled;
use std::sync::atomic::{AtomicUsize, Ordering};

/// paper-convergence at h = k = 1/4 to t = 1/2 (2 steps), Tresca friction.
fn base() -> Value {
    let mut s = crate::scene::presets::get("paper-convergence").unwrap();
    s["mesh"]["h"] = json!("1/4");
    s["time"] = json!({"t_end": "1/2", "k": "1/4"});
    s["friction"] = json!({"law": "tresca", "g": 1});
    s["solver"] = json!({"linear": "direct"});
    s
}

fn parse(doc: Value) -> Result<(SweepSpec, Value), ValidationErrors> {
    parse_with(&doc, "/sweep", &Bundled)
}

fn pointer_of(doc: Value) -> String {
    parse(doc).unwrap_err().0[0].pointer.clone()
}

#[test]
fn a_grid_is_every_combination_the_first_pointer_slowest() {
    let (spec, expanded) = parse(json!({
        "scene": base(),
        "vary": {"/friction/g": [0.05, 1, 2], "/damage/kappa": [0.1, 0.5]},
    }))
    .unwrap();
    assert_eq!(spec.mode, Mode::Grid);
    assert_eq!(expanded["mode"], "grid");
    let values: Vec<Vec<Value>> = spec.members.iter().map(|m| m.values.clone()).collect();
    assert_eq!(
        values,
        [
            [json!(0.05), json!(0.1)],
            [json!(0.05), json!(0.5)],
            [json!(1), json!(0.1)],
            [json!(1), json!(0.5)],
            [json!(2), json!(0.1)],
            [json!(2), json!(0.5)],
        ]
    );
    for m in &spec.members {
        assert_eq!(m.scene["friction"]["g"], m.values[0]);
        assert_eq!(m.scene["damage"]["kappa"], m.values[1]);
    }
    let (zip, _) = parse(json!({
        "scene": base(), "mode": "zip",
        "vary": {"/friction/g": [0.05, 1], "/damage/kappa": [0.1, 0.5]},
    }))
    .unwrap();
    assert_eq!(zip.members.len(), 2);
    assert_eq!(zip.members[1].values, [json!(1), json!(0.5)]);
}

#[test]
fn bad_sweeps_are_refused_at_their_member() {
    let vary = |v: Value| json!({"scene": base(), "vary": v});
    assert_eq!(
        pointer_of(vary(json!({"/friction/g": [-1, 1]}))),
        "/sweep/vary/~1friction~1g"
    );
    assert_eq!(
        pointer_of(vary(json!({"/friction/nope": [1]}))),
        "/sweep/vary/~1friction~1nope"
    );
    assert_eq!(
        pointer_of(vary(json!({"/nothing/here": [1]}))),
        "/sweep/vary/~1nothing~1here"
    );
    assert_eq!(
        pointer_of(vary(json!({"friction": [1]}))),
        "/sweep/vary/friction"
    );
    assert_eq!(
        pointer_of(vary(json!({"/friction/g": []}))),
        "/sweep/vary/~1friction~1g"
    );
    assert_eq!(pointer_of(vary(json!({}))), "/sweep/vary");
    assert_eq!(
        pointer_of(vary(json!({"/name": ["a", "b"]}))),
        "/sweep/vary/~1name"
    );
    let many: Vec<f64> = (1..=9).map(f64::from).collect();
    let m = parse(vary(json!({"/friction/g": many, "/damage/kappa": many}))).unwrap_err();
    assert_eq!(m.0[0].pointer, "/sweep/vary");
    assert!(m.0[0].message.contains("81 members"), "{}", m.0[0].message);
    let zip = json!({"scene": base(), "mode": "zip",
                     "vary": {"/friction/g": [1, 2], "/damage/kappa": [0.1]}});
    assert_eq!(pointer_of(zip), "/sweep/vary/~1damage~1kappa");
    let mode = json!({"scene": base(), "mode": "all", "vary": {"/friction/g": [1]}});
    assert_eq!(pointer_of(mode), "/sweep/mode");
    let unknown = json!({"scene": base(), "vary": {"/friction/g": [1]}, "steps": 3});
    assert_eq!(pointer_of(unknown), "/sweep/steps");
}

#[test]
fn the_largest_member_decides_admission() {
    let (spec, _) = parse(json!({
        "scene": base(),
        "vary": {"/mesh/h": ["1/4", "1/64"], "/friction/g": [1, 2]},
    }))
    .unwrap();
    let limits = Limits {
        max_nodes: Some(1000),
        ..Limits::default()
    };
    let e = spec.admit(&limits).unwrap_err();
    assert_eq!(e.pointer, "/sweep/vary/~1mesh~1h");
    assert!(e.message.contains("/mesh/h = \"1/64\""), "{}", e.message);
    let steps = spec
        .admit(&Limits {
            max_steps: Some(7),
            ..Limits::default()
        })
        .unwrap_err();
    assert_eq!((steps.needed, steps.allowed), (8, 7));
    // Each member is held to the stored-bytes limit of a job of its own (its output).
    let stored = spec
        .admit(&Limits {
            max_stored_bytes: Some(1),
            ..Limits::default()
        })
        .unwrap_err();
    assert_eq!(stored.pointer, "/sweep/scene/output");
    assert!(spec.admit(&Limits::default()).is_ok());
}

/// A 3 × 2 sweep gives the rows of six single runs, bit for bit; an equal member is computed
/// once; a member the caller knows is not computed.
#[test]
fn a_sweep_equals_its_single_runs_and_computes_each_member_once() {
    let (spec, _) = parse(json!({
        "scene": base(),
        "vary": {"/friction/g": [0.05, 1, 0.05], "/damage/kappa": [0.1, 0.5]},
    }))
    .unwrap();
    let steps = AtomicUsize::new(0);
    let progress = |_: usize, _: usize| {
        steps.fetch_add(1, Ordering::Relaxed);
        ControlFlow::Continue(())
    };
    let exec = Execution::default();
    let r = run(&spec, exec, &progress, &|_| None).unwrap();
    assert_eq!(r.rows.len(), 6);
    assert_eq!(
        r.computed, 4,
        "the members with g = 0.05 twice are computed once"
    );
    assert!(r.rows[4].cached && r.rows[5].cached);
    assert!(r
        .rows
        .iter()
        .any(|row| row.slip_nodes > 0 && row.max_slip_speed > 0.0));
    for (row, m) in r.rows.iter().zip(&spec.members) {
        let mut one = Run::<2>::new(m.problem.clone(), exec.settings).unwrap();
        let ControlFlow::Continue(()) = one.drive(&mut crate::run::ToEnd).unwrap();
        let state = one.sim().checkpoint_state();
        let summary = serde_json::to_value(one.summary()).unwrap();
        let single = SweepRow::from_run(&summary, &state, 2).unwrap();
        let bits = |r: &SweepRow| {
            [
                r.w_v,
                r.u_v,
                r.zeta_l2,
                r.zeta_min,
                r.min_zeta,
                r.max_slip_speed,
            ]
            .map(f64::to_bits)
        };
        assert_eq!(bits(row), bits(&single), "member {}", row.member);
        assert_eq!(row.slip_nodes, single.slip_nodes);
        assert_eq!(row.values["/friction/g"], m.values[0]);
    }
    // Progress: every step of the computed members, and only those.
    assert_eq!(steps.load(Ordering::Relaxed), 4 * 2);

    // The caller knows every member: nothing is computed.
    let known = |scene: &Value| {
        let p = crate::scene::validate(scene).unwrap();
        let mut one = Run::<2>::new(p, exec.settings).unwrap();
        let ControlFlow::Continue(()) = one.drive(&mut crate::run::ToEnd).unwrap();
        let state = one.sim().checkpoint_state();
        Some((serde_json::to_value(one.summary()).unwrap(), state))
    };
    let again = run(&spec, exec, &|_, _| ControlFlow::Continue(()), &known).unwrap();
    assert_eq!(again.computed, 0);
    assert!(again.rows.iter().all(|r| r.cached));
    assert_eq!(again.rows[3].w_v.to_bits(), r.rows[3].w_v.to_bits());

    let csv = r.csv();
    assert_eq!(csv.lines().count(), 7);
    assert!(
        csv.starts_with("member,/friction/g,/damage/kappa,w_V,"),
        "{csv}"
    );
    let svg = plot_svg(&r, "max_slip_speed", "/friction/g").unwrap();
    assert_eq!(
        svg.matches("<g class=\"line\">").count(),
        2,
        "one line per kappa"
    );
    assert!(svg.contains("/damage/kappa = 0.1"));
    assert!(plot_svg(&r, "nope", "/friction/g").is_none());
    assert!(plot_svg(&r, "w_V", "/nope").is_none());
}
