//! The full-space Newton method against the dense reduced problem (an independent solver of
//! the same minimisation), with the optimality conditions checked directly, on real velocity
//! operators: 2D rectangles (smoothed aggregation and geometric levels) and a 3D box, with
//! loads that make Γ3 all slip, all stick, or alternate, tiny and huge ω_i, and a
//! slip-weakening law near the smallness bound.

use contact_core::fem::{assembly, multilevel, DofMap, Geometry};
use contact_core::linalg::dense::min_eig_scaled;
use contact_core::linalg::multigrid::{Hierarchy, Params};
use contact_core::linalg::{schur_complement, Cholesky, Csr, SchurPath};
use contact_core::problem::FrictionLaw;
use contact_core::scene::{self, presets};
use contact_core::solve::semismooth_newton::{NewtonReport, SemismoothNewton};
use contact_core::solve::{friction_isotropic, friction_reduced, SolverSettings};
use nalgebra::DMatrix;
use serde_json::{json, Value};
use std::sync::Arc;

/// A velocity operator on all free DOFs with its hierarchy, and the data of its Γ3.
struct Case {
    k: Arc<Csr>,
    hierarchy: Arc<Hierarchy>,
    n_i: usize,
    block: usize,
    /// ω_i per Γ3 node.
    weights: Vec<f64>,
    /// Dense S, factor of K_II (the independent reference).
    s: DMatrix<f64>,
    k_ii: Cholesky,
}

fn case<const D: usize>(preset: &str, mesh: Value) -> Case {
    let mut doc = presets::get(preset).unwrap();
    doc["mesh"] = mesh;
    let problem = scene::validate(&doc).unwrap();
    let mesh = problem.mesh::<D>().unwrap();
    let geo = Geometry::new(&mesh);
    let dofs = DofMap::new(&mesh, &problem.boundary);
    let k = assembly::viscous_stiffness(&mesh, &geo, &dofs, 1.0, 0.5);
    let n_i = dofs.n_interior;
    let (blocks, levels) = multilevel::velocity_levels(&mesh, &dofs, dofs.n_free());
    let k = Arc::new(k);
    let hierarchy = Arc::new(Hierarchy::new(k.clone(), blocks, levels, Params::default()).unwrap());
    let k_ii = Cholesky::new(k.block(0..n_i, 0..n_i).lower_csc().as_ref()).unwrap();
    let (s, _) = schur_complement(&k, n_i, &k_ii, SchurPath::TrailingBlock);
    Case {
        weights: dofs
            .contact
            .iter()
            .step_by(D - 1)
            .map(|c| c.weight)
            .collect(),
        k,
        hierarchy,
        n_i,
        block: D - 1,
        s,
        k_ii,
    }
}

impl Case {
    fn n(&self) -> usize {
        self.k.nrows
    }

    /// A smooth interior load plus a Γ3 load whose tangential force at node i is `contact(i)`
    /// (block-vector of the node).
    fn load(&self, contact: impl Fn(usize) -> [f64; 2]) -> Vec<f64> {
        let mut f: Vec<f64> = (0..self.n())
            .map(|i| 0.01 * ((i as f64) * 0.013).sin())
            .collect();
        for i in 0..self.weights.len() {
            let v = contact(i);
            for r in 0..self.block {
                f[self.n_i + self.block * i + r] += self.weights[i] * v[r];
            }
        }
        f
    }

    /// The dense reduced solution: x on Γ3 from S, then w_I = K_II⁻¹ (f_I − K_IC x).
    fn reference(&mut self, f: &[f64], weights: &[f64], law: &FrictionLaw) -> Vec<f64> {
        let (n, n_i) = (self.n(), self.n_i);
        let k_ci = self.k.block(n_i..n, 0..n_i);
        let mut y = f[..n_i].to_vec();
        self.k_ii.solve_in_place(&mut y);
        let mut b = f[n_i..].to_vec();
        let mut ky = vec![0.0; n - n_i];
        k_ci.mul_vec(&y, &mut ky);
        b.iter_mut().zip(&ky).for_each(|(b, v)| *b -= v);
        let scale = f.iter().fold(f64::MIN_POSITIVE, |m, v| m.max(v.abs()));
        let settings = SolverSettings {
            tolerance: 1e-13,
            ..Default::default()
        };
        let mut x = vec![0.0; n - n_i];
        let p = friction_reduced::Reduced {
            s: &self.s,
            b: &b,
            weights,
            law,
            scale: Some(scale),
        };
        match self.block {
            1 => friction_reduced::solve(&p, &mut x, &settings, 0).unwrap(),
            _ => friction_isotropic::solve(&p, &mut x, &settings, 0).unwrap(),
        };
        let mut rhs = f[..n_i].to_vec();
        let mut kx = vec![0.0; n_i];
        k_ci.tmul_vec_add(&x, &mut kx);
        rhs.iter_mut().zip(&kx).for_each(|(r, v)| *r -= v);
        self.k_ii.solve_in_place(&mut rhs);
        rhs.extend_from_slice(&x);
        rhs
    }

    /// The full-space solver of this case with weights ω and `law`.
    fn newton(&self, weights: &[f64], law: FrictionLaw) -> SemismoothNewton {
        SemismoothNewton::new(
            self.k.clone().into(),
            self.hierarchy.clone(),
            self.n_i,
            self.block,
            weights.to_vec(),
            law,
        )
    }

    /// Tangential loads turning around the Γ3 plane, alternating in size between 0.5 and 2.
    fn turning_load(&self) -> Vec<f64> {
        self.load(|i| {
            let a = 0.7 * i as f64;
            let s = if i % 2 == 0 { 0.5 } else { 2.0 };
            [s * a.cos(), s * a.sin()]
        })
    }

    /// Solves with Newton from `w0`, checks the KKT conditions directly and the agreement
    /// with the dense reduced solution; returns the report.
    fn check(&mut self, f: &[f64], weights: &[f64], law: FrictionLaw, w0: &[f64]) -> NewtonReport {
        let mut newton = self.newton(weights, law.clone());
        let mut w = w0.to_vec();
        let rep = newton
            .solve(f, &mut w, &SolverSettings::default(), 1e-12, 0)
            .unwrap_or_else(|e| panic!("{law:?}: {e}"));
        let scale = f.iter().fold(f64::MIN_POSITIVE, |m, v| m.max(v.abs()));
        // Optimality, from K w − f itself.
        let mut g = vec![0.0; self.n()];
        self.k.mul_vec(&w, &mut g);
        g.iter_mut().zip(f).for_each(|(g, f)| *g -= f);
        for (j, gi) in g[..self.n_i].iter().enumerate() {
            assert!(gi.abs() <= 1e-10 * scale, "interior row {j}: {gi}");
        }
        for (i, &om) in weights.iter().enumerate() {
            let c = self.n_i + self.block * i;
            let x: Vec<f64> = w[c..c + self.block].to_vec();
            let gi: Vec<f64> = g[c..c + self.block].to_vec();
            let r = x.iter().map(|v| v * v).sum::<f64>().sqrt();
            let gn = gi.iter().map(|v| v * v).sum::<f64>().sqrt();
            if r == 0.0 {
                assert!(gn <= om * law.mu(0.0) + 1e-10 * scale, "stick node {i}");
            } else {
                // The reaction −g is the friction force ω μ(|x|) x/|x|, opposing the slip.
                for q in 0..self.block {
                    let want = -om * law.mu(r) * x[q] / r;
                    assert!((gi[q] - want).abs() <= 1e-10 * scale, "slip node {i}");
                }
            }
        }
        let reference = self.reference(f, weights, &law);
        let size = reference
            .iter()
            .fold(f64::MIN_POSITIVE, |m, v| m.max(v.abs()));
        let diff = w
            .iter()
            .zip(&reference)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(
            diff <= 1e-8 * size,
            "{law:?}: |w − w_dense| = {diff:.3e} of {size:.3e}"
        );
        rep
    }
}

fn tresca(g: f64) -> FrictionLaw {
    FrictionLaw::Tresca { g }
}

#[test]
fn two_dimensional_partitions_from_all_slip_to_all_stick() {
    for mesh in [json!({"h": "1/16"}), json!({"h": "1/32"})] {
        let mut c = case::<2>("paper-convergence", mesh);
        let zero = vec![0.0; c.n()];
        let weights = c.weights.clone();
        // A tangential Γ3 load of about 1 per unit length, alternating in sign node by node
        // between 0.5 and 2: g = 1 makes the nodes alternate between stick and slip.
        let f = c.load(|i| [if i % 2 == 0 { 0.5 } else { -2.0 }, 0.0]);
        let all_slip = c.check(&f, &weights, tresca(0.0), &zero);
        assert_eq!(all_slip.slip_nodes, weights.len());
        let tiny = c.check(&f, &weights, tresca(1e-4), &zero);
        assert!(tiny.slip_nodes > 0);
        let mixed = c.check(&f, &weights, tresca(1.0), &zero);
        assert!(
            mixed.slip_nodes > 0 && mixed.slip_nodes < weights.len(),
            "{mixed:?}"
        );
        let all_stick = c.check(&f, &weights, tresca(1e4), &zero);
        assert_eq!(all_stick.slip_nodes, 0);
        // Tiny and huge ω_i (the friction force scales with ω, the operator does not).
        for factor in [1e-6, 1e6] {
            let w: Vec<f64> = weights.iter().map(|v| v * factor).collect();
            c.check(&f, &w, tresca(1.0 / factor), &zero);
            c.check(&f, &w, tresca(1.0), &zero);
        }
        // A warm start that is wrong everywhere.
        let start: Vec<f64> = (0..c.n()).map(|i| ((i * 31) % 7) as f64 - 3.0).collect();
        c.check(&f, &weights, tresca(1.0), &start);
    }
}

#[test]
fn slip_weakening_near_the_smallness_bound() {
    let mut c = case::<2>("paper-convergence", json!({"h": "1/16"}));
    let weights = c.weights.clone();
    let d: Vec<f64> = weights.iter().map(|w| 1.0 / w.sqrt()).collect();
    // λ_min(W^-½ S W^-½) bounds c2τ = α (μ0 − μ1): take 90 % of it.
    let lambda = min_eig_scaled(&c.s, &d);
    let (mu0, mu1) = (1.2, 0.4);
    let law = FrictionLaw::SlipWeakening {
        mu0,
        mu1,
        alpha: 0.9 * lambda / (mu0 - mu1),
    };
    let f = c.load(|i| {
        [
            if i % 3 == 0 {
                0.6
            } else {
                1.5 + 0.1 * i as f64
            },
            0.0,
        ]
    });
    let rep = c.check(&f, &weights, law, &vec![0.0; c.n()]);
    assert!(rep.slip_nodes > 0);
}

#[test]
fn three_dimensional_isotropic_friction() {
    let mut c = case::<3>("box-exp3", json!({"h": "1/6"}));
    let zero = vec![0.0; c.n()];
    let weights = c.weights.clone();
    let f = c.turning_load();
    assert_eq!(
        c.check(&f, &weights, tresca(0.0), &zero).slip_nodes,
        weights.len()
    );
    let mixed = c.check(&f, &weights, tresca(1.0), &zero);
    assert!(
        mixed.slip_nodes > 0 && mixed.slip_nodes < weights.len(),
        "{mixed:?}"
    );
    assert_eq!(c.check(&f, &weights, tresca(1e4), &zero).slip_nodes, 0);
    let d: Vec<f64> = weights.iter().flat_map(|w| [1.0 / w.sqrt(); 2]).collect();
    let lambda = min_eig_scaled(&c.s, &d);
    let law = FrictionLaw::SlipWeakening {
        mu0: 1.2,
        mu1: 0.4,
        alpha: 0.9 * lambda / 0.8,
    };
    assert!(c.check(&f, &weights, law, &zero).slip_nodes > 0);
}

/// The multigrid path's smallness figure (Lanczos on W^{½} S⁻¹ W^{½}, no S formed) is the
/// dense path's λ_min(W^{-½} S W^{-½}), in 2D and 3D.
#[test]
fn lanczos_smallness_matches_the_dense_eigenvalue() {
    use contact_core::linalg::LinearSolver;
    use contact_core::solve::backend::multigrid::min_eig_by_lanczos;
    for c in [
        case::<2>("paper-convergence", json!({"h": "1/16"})),
        case::<3>("box-exp3", json!({"h": "1/6"})),
    ] {
        let per_dof: Vec<f64> = c
            .weights
            .iter()
            .flat_map(|w| std::iter::repeat_n(*w, c.block))
            .collect();
        let d: Vec<f64> = per_dof.iter().map(|w| 1.0 / w.sqrt()).collect();
        let dense = min_eig_scaled(&c.s, &d);
        let w_sqrt: Vec<f64> = per_dof.iter().map(|w| w.sqrt()).collect();
        let mut solver = LinearSolver::with_hierarchy(c.hierarchy.clone(), c.k.clone().into());
        let lanczos = min_eig_by_lanczos(&mut solver, c.n_i, &w_sqrt).unwrap();
        assert!(
            (lanczos - dense).abs() <= 1e-8 * dense,
            "Lanczos {lanczos} vs dense {dense}"
        );
    }
}

/// A start that is the solution but for rounding-sized slip at its stick nodes (what a
/// combination of earlier velocities holds at a node that has stopped slipping) is a KKT
/// residual of order one, which the contact sweep alone removes: no Newton step, no Krylov
/// iteration. Taking the forcing term before the sweep asked CG for one digit at a time and
/// cost 2–7 Newton iterations a step at 1/64.
#[test]
fn rounding_sized_slip_at_stick_nodes_is_removed_without_a_newton_step() {
    for (mut c, g) in [
        (case::<2>("paper-convergence", json!({"h": "1/16"})), 1.0),
        (case::<3>("box-exp3", json!({"h": "1/6"})), 1.0),
    ] {
        let weights = c.weights.clone();
        let f = c.turning_load();
        let mut solution = vec![0.0; c.n()];
        let mut newton = c.newton(&weights, tresca(g));
        newton
            .solve(&f, &mut solution, &SolverSettings::default(), 1e-12, 0)
            .unwrap();
        let size = solution.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let mut start = solution.clone();
        let mut noisy = 0;
        for i in 0..weights.len() {
            let dofs = c.n_i + c.block * i..c.n_i + c.block * (i + 1);
            if start[dofs.clone()].iter().all(|&v| v == 0.0) {
                start[dofs]
                    .iter_mut()
                    .enumerate()
                    .for_each(|(r, v)| *v = 1e-15 * size * (1.0 + r as f64 + i as f64).sin());
                noisy += 1;
            }
        }
        assert!(noisy > 0 && noisy < weights.len(), "a mixed case");
        let rep = c.check(&f, &weights, tresca(g), &start);
        assert_eq!(
            (rep.newton_iterations, rep.krylov_iterations),
            (0, 0),
            "{rep:?}"
        );
    }
}

/// Nodes that stop slipping between two solves (the start is the solution for a smaller g,
/// the solution for the larger g has fewer slipping nodes): the steps that land such nodes
/// at rest keep the solution exact (KKT conditions and agreement with the dense solve). How
/// much landing saves shows only at scale (docs/src/speed/speed.md: box-exp3, g = 2, 1/64);
/// on these small cases the iteration counts are within one of a line search alone.
#[test]
fn nodes_that_stop_slipping_come_to_rest_exactly() {
    for mut c in [
        case::<2>("paper-convergence", json!({"h": "1/16"})),
        case::<3>("box-exp3", json!({"h": "1/6"})),
    ] {
        let weights = c.weights.clone();
        let f = c.turning_load();
        let mut start = vec![0.0; c.n()];
        let mut all_slip = c.newton(&weights, tresca(0.2));
        let slipping = all_slip
            .solve(&f, &mut start, &SolverSettings::default(), 1e-12, 0)
            .unwrap();
        let rep = c.check(&f, &weights, tresca(1.0), &start);
        assert!(rep.slip_nodes < slipping.slip_nodes, "{rep:?}");
    }
}
