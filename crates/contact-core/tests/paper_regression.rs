//! Regression against an independent implementation of the same discrete choices (docs/src/explanation/numerics.md#model-and-scheme) (values given in
//! the issue that specified this core), and exact properties of the time stepping.

mod common;
use common::*;
use contact_core::fem::{assembly, loads, DofMap, Geometry, Slot};
use contact_core::laws::constitutive::elastic_stress;
use nalgebra::{DMatrix, DVector};

/// (|w|_V, |u|_V, |ζ|_Z0, min ζ) at t = T for paper-convergence at h = k = 1/n.
fn final_norms(n: usize) -> [f64; 4] {
    let sim = run(problem("paper-convergence", n, n, &[]));
    let s = &sim;
    let mut scratch = vec![0.0; s.mesh.n_nodes()];
    let geo = Geometry::new(&s.mesh);
    let m = assembly::mass(&s.mesh, &geo);
    [
        contact_core::fem::norms::strain_norm(&s.mesh, &geo, &s.w),
        contact_core::fem::norms::strain_norm(&s.mesh, &geo, &s.state.u),
        contact_core::fem::norms::mass_norm(&m, &s.state.zeta, &mut scratch),
        s.state.zeta.iter().cloned().fold(f64::INFINITY, f64::min),
    ]
}

#[test]
fn paper_convergence_h16_matches_independent_implementation() {
    let expect = [0.1449530872, 0.2277254980, 0.7630437363, 0.5199017467];
    let got = final_norms(16);
    for (g, e) in got.iter().zip(&expect) {
        assert!(rel(*g, *e) < 1e-7, "got {got:?}, expected {expect:?}");
    }
}

#[test]
fn paper_convergence_h32_matches_independent_implementation() {
    let expect = [0.1498299324, 0.2286652754, 0.7631022370, 0.5052263446];
    let got = final_norms(32);
    for (g, e) in got.iter().zip(&expect) {
        assert!(rel(*g, *e) < 1e-7, "got {got:?}, expected {expect:?}");
    }
}

/// With k = 1/2: ζ_1 = 1 (no strain at t = 0 gives φ = 0), and k·B = A for the paper's
/// moduli (k·2μ = 2η, k·λ = ξ), so the elastic term of step 2 cancels the load exactly and
/// w_2 = 0 (every Γ3 node sticks: x = 0 satisfies the friction law with zero force).
#[test]
fn k_one_half_makes_the_final_velocity_vanish() {
    let mut w_v = Vec::new();
    run_checked(problem("paper-convergence", 8, 2, &[]), |_, r| {
        w_v.push(r.w_v)
    });
    assert_eq!(w_v.len(), 2);
    assert!(w_v[0] > 0.01);
    assert!(
        w_v[1] < 1e-12 * w_v[0],
        "w_2 = {} vs w_1 = {}",
        w_v[1],
        w_v[0]
    );
}

/// Experiment 1 has no contact: each velocity step is the linear system K w = f_n − B-term.
/// Solve it independently with a dense Cholesky (nalgebra) from the library's assembly and
/// compare every step's velocity.
#[test]
fn experiment_1_matches_a_direct_linear_solve() {
    let p = problem("paper-exp1", 4, 8, &[]);
    let mut sim =
        contact_core::solve::stepper::Simulation::<2>::new(p, Default::default()).unwrap();
    let mesh = sim.mesh.clone();
    let geo = Geometry::new(&mesh);
    let dofs = DofMap::new(&mesh, &sim.problem.boundary);
    assert_eq!(dofs.n_contact(), 0);
    let visc = sim.problem.material.viscosity;
    let k = assembly::viscous_stiffness(&mesh, &geo, &dofs, visc.eta, visc.xi);
    let n = dofs.n_free();
    let dense = DMatrix::from_fn(n, n, |i, j| k.get(i, j));
    let chol = dense.cholesky().expect("SPD");
    while !sim.finished() {
        let (u_prev, z_prev) = (sim.state.u.clone(), sim.state.zeta.clone());
        let t = (sim.state.step + 1) as f64 * sim.problem.k();
        sim.step().unwrap();
        // f = ∫ f0·v + ∫_Γ2 f2·v − (B(ε(u_{n−1}), ζ̄_{n−1}), ε(v)).
        let b: Vec<_> = (0..mesh.n_cells())
            .map(|e| {
                let zbar = mesh.triangle(e).iter().map(|&i| z_prev[i]).sum::<f64>() / 3.0;
                elastic_stress(
                    &sim.problem.material.elasticity,
                    &geo.strain(&mesh, e, &u_prev),
                    zbar,
                )
            })
            .collect();
        let mut f = vec![0.0; 2 * mesh.n_nodes()];
        loads::add_body_force(&mesh, &geo, &sim.problem.body_force, t, &mut f);
        loads::add_tractions(&mesh, &sim.problem.boundary, t, &mut f);
        loads::add_stress_divergence(
            &contact_core::fem::NodeCells::new(&mesh),
            &geo,
            |e| b[e],
            &mut f,
        );
        let mut ff = vec![0.0; n];
        dofs.to_free(&f, &mut ff);
        let w = chol.solve(&DVector::from_vec(ff));
        let scale = w.amax();
        for (g, s) in dofs.slot.iter().enumerate() {
            let expect = match *s {
                Slot::Free(i) => w[i],
                Slot::Fixed => 0.0,
            };
            assert!(
                (sim.w[g] - expect).abs() <= 1e-11 * scale,
                "step {}: dof {g}",
                sim.state.step
            );
        }
    }
    // The body sags under f0 = (0, −0.2): the free end moves down.
    let tip = mesh.nodes.iter().position(|p| *p == [2.0, 1.0]).unwrap();
    assert!(sim.state.u[2 * tip + 1] < 0.0);
}
