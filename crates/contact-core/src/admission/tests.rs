use super::*;
use crate::scene::{self, presets, Overrides};
use serde_json::{json, Value};

/// box-exp3 at h = 1/n, N = 8 steps, with `solver.linear` = `linear`.
fn boxed(n: usize, linear: &str) -> Problem {
    let mut doc = presets::get("box-exp3").unwrap();
    scene::apply_overrides(
        &mut doc,
        &Overrides {
            h: Some(json!(format!("1/{n}"))),
            k: Some(json!("1/8")),
            t_end: None,
        },
    );
    doc["solver"] = json!({ "linear": linear });
    scene::validate(&doc).unwrap()
}

fn limits(max_memory: Option<u64>) -> Limits {
    Limits {
        max_memory,
        ..Limits::default()
    }
}

#[test]
fn a_demanded_direct_path_over_the_memory_limit_is_refused_at_the_solver_with_its_figures() {
    let p = boxed(24, "direct");
    let predicted = memory::predict(&p).direct;
    let limit = predicted / 2;
    let e = check_run(&p, &limits(Some(limit)), &Pointers::scene()).unwrap_err();
    assert_eq!(e.pointer, "/solver/linear");
    assert_eq!(e.limit, Limit::Memory);
    assert_eq!((e.needed, e.allowed), (predicted, limit));
    // A study's scene fixes the solver of every run: the run's mesh member is blamed.
    let at = Pointers {
        solver: None,
        mesh: "/study/reference/h".into(),
        ..Pointers::scene()
    };
    assert_eq!(
        check_run(&p, &limits(Some(limit)), &at)
            .unwrap_err()
            .pointer,
        "/study/reference/h"
    );
    // Above the prediction the same run is admitted on the path it demands.
    let fit = check_run(&p, &limits(Some(predicted)), &Pointers::scene()).unwrap();
    assert_eq!(
        (fit.path, fit.memory_bytes),
        (LinearPath::Direct, predicted)
    );
}

#[test]
fn auto_falls_back_to_the_path_that_fits() {
    let p = boxed(24, "auto");
    let pred = memory::predict(&p);
    let (small, large) = if pred.direct < pred.multigrid {
        (LinearPath::Direct, LinearPath::Multigrid)
    } else {
        (LinearPath::Multigrid, LinearPath::Direct)
    };
    let between = pred.direct.min(pred.multigrid) + pred.direct.abs_diff(pred.multigrid) / 2;
    let fit = check_run(&p, &limits(Some(between)), &Pointers::scene()).unwrap();
    assert_eq!(
        fit.path, small,
        "only the smaller path fits under {between}"
    );
    let unlimited = check_run(&p, &limits(None), &Pointers::scene()).unwrap();
    assert!(unlimited.path == small || unlimited.path == large);
    let e = check_run(&p, &limits(Some(1 << 20)), &Pointers::scene()).unwrap_err();
    assert_eq!(e.pointer, "/mesh/h", "nothing fits: the mesh is blamed");
}

#[test]
fn nodes_steps_and_stored_bytes_are_refused_at_their_members() {
    let p = boxed(8, "auto");
    let nodes = p.n_nodes();
    let cap = |l: Limits| check_run(&p, &l, &Pointers::scene());
    let e = cap(Limits {
        max_nodes: Some(nodes - 1),
        ..Limits::default()
    })
    .unwrap_err();
    assert_eq!(
        (e.pointer.as_str(), e.limit, e.needed, e.allowed),
        ("/mesh/h", Limit::Nodes, nodes as u64, nodes as u64 - 1)
    );
    let e = cap(Limits {
        max_steps: Some(7),
        ..Limits::default()
    })
    .unwrap_err();
    assert_eq!((e.pointer.as_str(), e.needed), ("/time/k", 8));
    let stored = stored_bytes(&p);
    assert!(stored > 0);
    let e = cap(Limits {
        max_stored_bytes: Some(stored - 1),
        ..Limits::default()
    })
    .unwrap_err();
    assert_eq!(
        (e.pointer.as_str(), e.limit),
        ("/output", Limit::StoredBytes)
    );
    let fit = cap(Limits {
        max_nodes: Some(nodes),
        max_steps: Some(8),
        max_stored_bytes: Some(stored),
        max_memory: None,
    })
    .unwrap();
    assert_eq!((fit.nodes, fit.stored_bytes), (nodes, stored));
}

#[test]
fn stored_bytes_count_the_selected_fields_at_the_stored_steps() {
    // 2D paper-exp3 (the rectangle (0, 2) × (0, 1)) at h = 1/4: 9 × 5 = 45 nodes; 4 steps,
    // u and ζ only, every step stored: 4 × (8 × (2 + 1) × 45 + 64) bytes, counted by hand.
    let mut doc: Value = presets::get("paper-exp3").unwrap();
    scene::apply_overrides(
        &mut doc,
        &Overrides {
            h: Some(json!("1/4")),
            k: Some(json!("1/4")),
            t_end: None,
        },
    );
    doc["output"] = json!({ "fields": ["u", "zeta"], "every": 1 });
    let p = scene::validate(&doc).unwrap();
    assert_eq!((p.n_nodes(), p.steps), (45, 4));
    assert_eq!(stored_bytes(&p), 4 * (8 * 3 * 45 + 64));
}

#[test]
fn the_stored_step_count_is_the_count_of_stored_steps() {
    use crate::problem::OutputSpec;
    let mut doc: Value = presets::get("paper-exp3").unwrap();
    for (every, last) in [
        (0, false),
        (0, true),
        (1, false),
        (3, true),
        (3, false),
        (7, true),
    ] {
        doc["output"] = json!({ "every": every, "last": last });
        let output: OutputSpec = scene::validate(&doc).unwrap().output;
        for steps in [0, 1, 2, 6, 7, 20, 21] {
            let counted = (1..=steps).filter(|&n| output.stores(n, steps)).count();
            assert_eq!(
                output.stored_steps(steps),
                counted,
                "every {every}, last {last}, N {steps}"
            );
        }
    }
}

#[test]
fn stored_bytes_saturate_instead_of_overflowing() {
    // A 3D box at 1/4096 with 2^26 steps, everything stored: far beyond any limit, but a
    // number (the target study's planner asks about such candidates).
    let mut p = boxed(4, "auto");
    p.cells_per_unit = 4096;
    p.steps = 1 << 26;
    p.output.every = 1;
    assert_eq!(stored_bytes(&p), u64::MAX);
}
