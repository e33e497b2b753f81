//! The a posteriori estimator on whole runs ([`contact_core::a_posteriori`]): under uniform
//! refinement it decreases as the true error does, its efficiency index (the estimate over
//! the run ÷ the true error (k Σ_n |w(t_n) − w_h(t_n)|²_V)^½ against a run 4–16× finer)
//! stays in a band, a resumed run estimates as an uninterrupted one, and a run that does not
//! ask computes nothing. On a manufactured smooth solution of the velocity operator alone
//! it converges at the true error's order 1.

mod common;

use common::dirichlet;
use contact_core::a_posteriori::{Estimator, Parts, StepData};
use contact_core::fem::prolongation::prolongate;
use contact_core::fem::{norms, CellTensors, Geometry};
use contact_core::mesh::Mesh;
use contact_core::problem::Problem;
use contact_core::run::run;
use contact_core::scene::{self, presets, Overrides};
use contact_core::solve::stepper::Simulation;
use contact_core::solve::SolverSettings;
use serde_json::{json, Value};
use std::ops::ControlFlow;

/// A run's mesh, w at every step, and the estimate over the run.
struct Level<const D: usize> {
    mesh: Mesh<D>,
    w: Vec<Vec<f64>>,
    estimate: Parts,
    k: f64,
}

fn level<const D: usize>(p: Problem) -> Level<D> {
    let k = p.k();
    let mut w = Vec::new();
    let mut mesh = None;
    let summary = run::<D>(p, SolverSettings::default(), |sim: &Simulation<D>, _| {
        w.push(sim.w.clone());
        mesh.get_or_insert_with(|| (*sim.mesh).clone());
        ControlFlow::Continue(())
    })
    .unwrap();
    Level {
        mesh: mesh.unwrap(),
        w,
        estimate: summary.estimate.unwrap(),
        k,
    }
}

/// (k Σ_n |w(t_n) − w_h(t_n)|²_V)^½ over the coarse level's steps, with the reference's w
/// at the same times (its steps a whole number of times shorter) and the coarse w
/// interpolated onto its (nested) mesh.
fn true_error<const D: usize>(coarse: &Level<D>, reference: &Level<D>) -> f64 {
    let geo = Geometry::new(&reference.mesh);
    let r = (coarse.k / reference.k).round() as usize;
    let mut sum = 0.0;
    for (n, w) in coarse.w.iter().enumerate() {
        let fine = prolongate(&coarse.mesh, w, D, &reference.mesh).unwrap();
        let d: Vec<f64> = reference.w[(n + 1) * r - 1]
            .iter()
            .zip(&fine)
            .map(|(a, b)| a - b)
            .collect();
        let e = norms::strain_norm(&reference.mesh, &geo, &d);
        sum += coarse.k * e * e;
    }
    sum.sqrt()
}

/// A resolution: h for a rectangle, or the polygon's h with red refinements; and k.
#[derive(Clone, Copy)]
enum At {
    Rectangle(&'static str),
    Refined(usize, &'static str),
}

fn scene(preset: &str, at: At) -> Problem {
    let mut doc: Value = presets::get(preset).unwrap();
    match at {
        At::Rectangle(hk) => scene::apply_overrides(
            &mut doc,
            &Overrides {
                h: Some(json!(hk)),
                k: Some(json!(hk)),
                t_end: None,
            },
        ),
        At::Refined(r, k) => {
            doc["mesh"]["h"] = json!("1/2");
            doc["mesh"]["refine"] = json!(r);
            doc["time"]["k"] = json!(k);
        }
    }
    doc["output"] = json!({"every": 0, "last": true, "fields": [], "estimate": true});
    scene::validate(&doc).unwrap()
}

/// The estimates and true errors of `levels` against `reference`.
fn ladder<const D: usize>(preset: &str, levels: &[At], reference: At) -> Vec<(f64, f64)> {
    let reference = level::<D>(scene(preset, reference));
    levels
        .iter()
        .map(|&at| {
            let l = level::<D>(scene(preset, at));
            let row = (l.estimate.velocity.total, true_error(&l, &reference));
            eprintln!(
                "{preset}, k = {}: estimate {:.4e}, true error {:.4e}, index {:.3}",
                l.k,
                row.0,
                row.1,
                row.0 / row.1
            );
            row
        })
        .collect()
}

/// Every index (estimate ÷ true error) in [1, 10], the largest at most 3× the smallest,
/// and both columns decreasing.
fn check_band(preset: &str, rows: &[(f64, f64)]) {
    let index: Vec<f64> = rows.iter().map(|(eta, e)| eta / e).collect();
    let (lo, hi) = index.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &i| {
        (lo.min(i), hi.max(i))
    });
    assert!(
        lo >= 1.0 && hi <= 10.0 && hi <= 3.0 * lo,
        "{preset}: indices {index:?}"
    );
    for w in rows.windows(2) {
        assert!(w[1].0 < w[0].0 && w[1].1 < w[0].1, "{preset}: {rows:?}");
    }
}

#[test]
fn the_estimate_follows_the_true_error_on_the_convergence_scene() {
    let rows = ladder::<2>(
        "paper-convergence",
        &[
            At::Rectangle("1/4"),
            At::Rectangle("1/8"),
            At::Rectangle("1/16"),
        ],
        At::Rectangle("1/64"),
    );
    check_band("paper-convergence", &rows);
    // Its observed order within 0.25 of the true error's (0.65 against 0.84 and 0.75
    // against 0.91 when this was written: the jumps' preasymptotic range).
    for w in rows.windows(2) {
        let (oe, ot) = ((w[0].0 / w[1].0).log2(), (w[0].1 / w[1].1).log2());
        assert!((oe - ot).abs() <= 0.25 && oe > 0.5, "orders {oe} and {ot}");
    }
}

#[test]
fn the_efficiency_index_stays_in_its_band_at_a_re_entrant_corner() {
    let rows = ladder::<2>(
        "l-bracket",
        &[
            At::Refined(0, "1/4"),
            At::Refined(1, "1/8"),
            At::Refined(2, "1/16"),
        ],
        At::Refined(5, "1/64"),
    );
    check_band("l-bracket", &rows);
}

/// The 3D box of experiment 3 (Kuhn tetrahedra, nested in the reference's lattice).
#[test]
fn the_efficiency_index_stays_in_its_band_on_the_box() {
    let rows = ladder::<3>(
        "box-exp3",
        &[At::Rectangle("1/2"), At::Rectangle("1/4")],
        At::Rectangle("1/16"),
    );
    check_band("box-exp3", &rows);
}

#[test]
fn a_resumed_run_estimates_as_an_uninterrupted_one() {
    let p = scene("paper-exp3", At::Rectangle("1/8"));
    let mut whole = Simulation::<2>::new(p.clone(), SolverSettings::default()).unwrap();
    let reports: Vec<_> = (0..4).map(|_| whole.step().unwrap()).collect();
    let mut first = Simulation::<2>::new(p.clone(), SolverSettings::default()).unwrap();
    first.step().unwrap();
    first.step().unwrap();
    let state = first.checkpoint_state();
    assert_eq!(state.w.len(), first.w.len(), "the checkpoint keeps w_n");
    let mut resumed = Simulation::<2>::new(p.clone(), SolverSettings::default()).unwrap();
    resumed.restore(state);
    for r in &reports[2..] {
        let again = resumed.step().unwrap();
        assert_eq!(again.estimate, r.estimate, "step {}", r.n);
        assert!(r.estimate.unwrap().velocity.time > 0.0);
    }
    let fields = resumed.fields();
    assert_eq!(fields.estimate.unwrap().len(), resumed.mesh.n_cells());
    // From a state without w_n (a run that did not estimate): no time indicator for the
    // first step, the spatial parts as before.
    let mut state = first.checkpoint_state();
    state.w.clear();
    let mut blind = Simulation::<2>::new(p, SolverSettings::default()).unwrap();
    blind.restore(state);
    let (e, whole) = (
        blind.step().unwrap().estimate.unwrap(),
        reports[2].estimate.unwrap(),
    );
    assert_eq!(e.velocity.time, 0.0);
    assert_eq!(
        (e.velocity.jump, e.velocity.traction, e.damage),
        (whole.velocity.jump, whole.velocity.traction, whole.damage)
    );
}

#[test]
fn a_run_that_does_not_ask_estimates_nothing() {
    let mut p = scene("paper-exp3", At::Rectangle("1/4"));
    p.output.estimate = false;
    p.output.fields.zeta = true;
    let summary = run::<2>(p, SolverSettings::default(), |sim: &Simulation<2>, _| {
        assert!(sim.fields().estimate.is_none());
        assert!(sim.checkpoint_state().w.is_empty());
        ControlFlow::Continue(())
    })
    .unwrap();
    assert!(summary.estimate.is_none());
    assert!(summary.steps.iter().all(|s| s.estimate.is_none()));
    let json = serde_json::to_value(&summary).unwrap();
    assert!(json.get("estimate").is_none() && json["steps"][0].get("estimate").is_none());
}

/// w* = (x²y, xy²) on the unit square with w = w* on the boundary and the body force of
/// tests/unstructured.rs (η = 1, ξ = 1/2: f = −div σ = −8 (y, x)): the estimate of the
/// discrete solution has the true error's order 1 and an index in a narrow band.
#[test]
fn on_a_manufactured_solution_the_estimate_converges_with_the_error() {
    let mut doc = presets::get("paper-exp1").unwrap();
    doc["domain"] = json!({"width": 1, "height": 1});
    doc["material"]["viscosity"] = json!({"eta": 1, "xi": 0.5});
    doc["loads"] = json!({"f0": ["-8*y", "-8*x"]});
    doc["boundary"] = json!([
        {"type": "clamped", "from": [0, 0], "to": [1, 0]},
        {"type": "clamped", "from": [1, 0], "to": [1, 1]},
        {"type": "clamped", "from": [1, 1], "to": [0, 1]},
        {"type": "clamped", "from": [0, 1], "to": [0, 0]},
    ]);
    doc.as_object_mut().unwrap().remove("damage");
    let p = scene::validate(&doc).unwrap();
    let exact = |q: [f64; 2]| [q[0] * q[0] * q[1], q[0] * q[1] * q[1]];
    let mut rows = Vec::new();
    for n in [4, 8, 16, 32] {
        let mut mesh = Mesh::rectangle(1.0, 1.0, n, n, contact_core::mesh::MeshPattern::Diagonal);
        let supports: Vec<_> = p.boundary.iter().map(|b| b.support.clone()).collect();
        mesh.tag_boundary(&supports).unwrap();
        let geo = Geometry::new(&mesh);
        let w = dirichlet::solve(&mesh, (1.0, 0.5), &p.body_force, exact);
        // ‖ε(w* − w_h)‖ by the edge-midpoint rule, exact for the quadratic integrand.
        let mut e2 = 0.0;
        for (t, tri) in mesh.triangles().iter().enumerate() {
            let h = geo.strain(&mesh, t, &w);
            for a in 0..3 {
                let (q, r) = (mesh.nodes[tri[a]], mesh.nodes[tri[(a + 1) % 3]]);
                let (x, y) = (0.5 * (q[0] + r[0]), 0.5 * (q[1] + r[1]));
                let d = [
                    2.0 * x * y - h[(0, 0)],
                    2.0 * x * y - h[(1, 1)],
                    0.5 * (x * x + y * y) - h[(0, 1)],
                ];
                e2 += geo.measure(t) / 3.0 * (d[0] * d[0] + d[1] * d[1] + 2.0 * d[2] * d[2]);
            }
        }
        let zero = CellTensors::<2>::zeros(mesh.n_cells());
        let data = StepData {
            t: 0.0,
            k: 1.0,
            m_a: 2.0,
            w: &w,
            w_prev: None,
            b: &zero,
            u_prev: &vec![0.0; w.len()],
            zeta_prev: &[],
            zeta: &[],
        };
        let est = Estimator::new(&p, &mesh, &geo).step(&p, &mesh, &geo, &data);
        let v = est.parts.velocity;
        assert!(
            v.traction == 0.0 && v.friction == 0.0 && v.time == 0.0,
            "{v:?}"
        );
        eprintln!(
            "n = {n}: estimate {:.4e}, error {:.4e}, index {:.3}",
            v.total,
            e2.sqrt(),
            v.total / e2.sqrt()
        );
        rows.push((v.total, e2.sqrt()));
    }
    for w in rows.windows(2) {
        let (oe, ot) = ((w[0].0 / w[1].0).log2(), (w[0].1 / w[1].1).log2());
        assert!(
            (0.9..1.1).contains(&ot) && (oe - ot).abs() < 0.1,
            "orders {oe} and {ot}"
        );
    }
    check_band("manufactured", &rows);
}
