//! After every step, each sub-problem's optimality conditions hold for the data the step
//! built, checked against operators assembled here (by element triplets, whatever the path):
//! the velocity step (3.13) on the free DOFs (interior rows of K w − f vanish, the Tresca law
//! holds node by node on Γ3, the normal velocity is zero there) and the damage step (3.10)
//! (box constraints and complementarity).

use super::*;
use crate::fem::assembly;
use crate::scene::{self, presets};
use serde_json::json;

/// paper-exp3 at h = 1/8, three steps, Tresca bound `g`, on the path `linear`.
fn problem(linear: &str, g: f64) -> Problem {
    let mut doc = presets::get("paper-exp3").unwrap();
    doc["mesh"]["h"] = json!("1/8");
    doc["time"] = json!({"T": 1, "N": 3});
    doc["friction"] = json!({"law": "tresca", "g": g});
    doc["solver"] = json!({"linear": linear});
    scene::validate(&doc).unwrap()
}

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0f64, |m, x| m.max(x.abs()))
}

/// The velocity step's conditions, with `g` the Tresca bound; returns the slipping nodes.
fn velocity_kkt(sim: &Simulation<2>, g: f64) -> usize {
    let visc = sim.problem.material.viscosity;
    let k = assembly::viscous_stiffness(&sim.mesh, &sim.geo, &sim.dofs, visc.eta, visc.xi);
    let (f, w) = (&sim.velocity.load_free, &sim.velocity.w_free);
    let mut r = vec![0.0; f.len()];
    k.mul_vec(w, &mut r);
    r.iter_mut().zip(f).for_each(|(r, f)| *r -= f);
    let tol = 1e-9 * max_abs(f);
    let n_i = sim.dofs.n_interior;
    assert!(
        max_abs(&r[..n_i]) <= tol,
        "interior residual {}",
        max_abs(&r[..n_i])
    );
    let mut slipping = 0;
    for (i, c) in sim.dofs.contact.iter().enumerate() {
        let (x, rc, bound) = (w[n_i + i], r[n_i + i], c.weight * g);
        if x == 0.0 {
            assert!(
                rc.abs() <= bound + tol,
                "stuck node {}: |{rc}| > {bound}",
                c.node
            );
        } else {
            slipping += 1;
            let v = (rc + bound * x.signum()).abs();
            assert!(
                v <= tol,
                "slipping node {}: force {rc}, bound {bound}",
                c.node
            );
        }
    }
    let scale = max_abs(&sim.w).max(f64::MIN_POSITIVE);
    for (node, n) in &sim.dofs.normals {
        let wn = sim.w[2 * node] * n[0] + sim.w[2 * node + 1] * n[1];
        assert!(wn.abs() <= 1e-14 * scale, "w·n = {wn} at node {node}");
    }
    slipping
}

/// The damage step's conditions: 0 ≤ ζ ≤ 1 and, with λ = Hζ − g, λ = 0 where 0 < ζ < 1,
/// λ ≥ 0 at 0, λ ≤ 0 at 1. Returns the nodes at a bound.
fn damage_kkt(sim: &Simulation<2>, h: &Csr) -> usize {
    let g = &sim.damage.as_ref().unwrap().g;
    let zeta = &sim.state.zeta;
    let mut lambda = vec![0.0; zeta.len()];
    h.mul_vec(zeta, &mut lambda);
    lambda.iter_mut().zip(g).for_each(|(l, g)| *l -= g);
    let tol = 1e-9 * max_abs(g);
    let mut at_bound = 0;
    for (i, (&z, &l)) in zeta.iter().zip(&lambda).enumerate() {
        assert!((0.0..=1.0).contains(&z), "ζ = {z} at node {i}");
        if z == 0.0 {
            assert!(l >= -tol, "node {i} at 0: λ = {l}");
        } else if z == 1.0 {
            assert!(l <= tol, "node {i} at 1: λ = {l}");
        } else {
            assert!(l.abs() <= tol, "free node {i}: λ = {l}");
        }
        at_bound += usize::from(z == 0.0 || z == 1.0);
    }
    at_bound
}

#[test]
fn every_step_meets_both_sub_problems_optimality_conditions() {
    for linear in ["direct", "multigrid"] {
        let mut slipped = 0;
        for g in [2.0, 20.0] {
            let p = problem(linear, g);
            let mut sim = Simulation::<2>::new(p, SolverSettings::default()).unwrap();
            let d = sim.problem.damage.clone().unwrap();
            let m = assembly::mass(&sim.mesh, &sim.geo);
            let l = assembly::laplacian(&sim.mesh, &sim.geo);
            let h = assembly::combine(1.0 / sim.problem.k(), &m, d.kappa, &l);
            while !sim.finished() {
                let report = sim.step().unwrap();
                let slipping = velocity_kkt(&sim, g);
                assert_eq!(slipping, report.slip_nodes);
                slipped += slipping;
                damage_kkt(&sim, &h);
            }
        }
        // Both sides of the friction law were exercised.
        assert!(slipped > 0, "{linear}: no step slipped");
    }
}

/// A checkpoint's state with its warm starts restores a run that repeats the uninterrupted
/// one bit for bit on the direct path.
#[test]
fn a_restored_run_repeats_the_uninterrupted_one() {
    let p = problem("direct", 2.0);
    let mut whole = Simulation::<2>::new(p.clone(), SolverSettings::default()).unwrap();
    let first = whole.step().unwrap();
    let saved = whole.checkpoint_state();
    let rest: Vec<StepReport> = (0..2).map(|_| whole.step().unwrap()).collect();
    let mut resumed = Simulation::<2>::new(p, SolverSettings::default()).unwrap();
    resumed.restore(saved);
    assert_eq!(resumed.state.step, first.n);
    let again: Vec<StepReport> = (0..2).map(|_| resumed.step().unwrap()).collect();
    assert_eq!(rest, again);
    assert!(resumed.finished());
}

/// The damage solve starts from ζ_{n−1} + (ζ_{n−1} − ζ_{n−2}) clipped to [0, 1]: nothing is
/// predicted before two states are known (the first step, a resumed run), and the state
/// the prediction reads moves on one step at a time.
#[test]
fn the_damage_start_is_the_clipped_linear_extrapolation() {
    let mut sim =
        Simulation::<2>::new(problem("multigrid", 1.0), SolverSettings::default()).expect("set-up");
    let d = sim.damage.as_mut().expect("paper-exp3 has damage");
    let n = d.next.len();
    d.before.clear();
    let first: Vec<f64> = (0..n).map(|i| 0.5 + 0.1 * (i % 3) as f64).collect();
    d.next.clone_from(&first);
    d.predict();
    assert_eq!(d.next, first, "no prediction from one state");
    // ζ_{n−1} − ζ_{n−2} of 0.3, −0.6 and 0.05 around 0.5, 0.6, 0.7.
    let last: Vec<f64> = (0..n)
        .map(|i| first[i] + [0.3, -0.6, 0.05][i % 3])
        .collect();
    d.next.clone_from(&last);
    d.predict();
    for i in 0..n {
        let want = [1.0, 0.0, 0.8][i % 3];
        assert!((d.next[i] - want).abs() < 1e-15, "node {i}: {}", d.next[i]);
        assert_eq!(d.before[i], last[i]);
    }
}

/// A run whose outputs read no stress keeps no B_{n−1} and forms each cell's where the
/// velocity load reads it: the same steps, bit for bit, as the run that keeps it, in 2D and
/// in 3D (box-exp3 at h = 1/4, damage and contact on).
#[test]
fn a_run_without_stress_outputs_forms_b_where_it_reads_it_with_the_same_bits() {
    fn runs<const D: usize>(p: Problem) {
        let mut kept = p.clone();
        kept.output.fields = crate::problem::FieldSet {
            sigma: true,
            ..Default::default()
        };
        let mut formed = p;
        formed.output.fields = Default::default();
        formed.output.estimate = false;
        assert!(kept.output.keeps_history_stress() && !formed.output.keeps_history_stress());
        let mut a = Simulation::<D>::new(kept, SolverSettings::default()).unwrap();
        let mut b = Simulation::<D>::new(formed, SolverSettings::default()).unwrap();
        assert!(a.b.is_some() && b.b.is_none());
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        for _ in 0..3 {
            assert_eq!(a.step().unwrap(), b.step().unwrap());
            assert_eq!(bits(&a.state.u), bits(&b.state.u));
            assert_eq!(bits(&a.state.zeta), bits(&b.state.zeta));
        }
        assert!(a.fields().sigma.is_some());
    }
    runs::<2>(problem("direct", 2.0));
    let mut doc = presets::get("box-exp3").unwrap();
    doc["mesh"]["h"] = json!("1/4");
    doc["time"] = json!({"T": 1, "N": 3});
    runs::<3>(scene::validate(&doc).unwrap());
}
