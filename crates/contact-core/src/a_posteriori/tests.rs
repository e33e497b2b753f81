use super::*;
use crate::laws::constitutive::viscous_stress;
use crate::problem::FrictionLaw;
use crate::scene::{self, presets};
use serde_json::json;

/// The unit square, clamped on x = 0, loaded on the other three sides by the tractions
/// σ ν of the constant stress `sigma`, no body force; with damage unless `damage` is false.
fn patch_problem(sigma: &Tensor<2>, damage: bool) -> Problem {
    let mut doc = presets::get("paper-exp1").unwrap();
    let f2 = |n: [f64; 2]| {
        let t = mul(sigma, &n);
        json!([t[0], t[1]])
    };
    doc["domain"] = json!({"width": 1, "height": 1});
    doc["mesh"] = json!({"h": "1/4"});
    doc["time"] = json!({"t_end": 1, "k": "1/4"});
    doc["loads"] = json!({"f0": [0, 0]});
    doc["boundary"] = json!([
        {"type": "clamped", "from": [0, 0], "to": [0, 1]},
        {"type": "traction", "from": [1, 0], "to": [1, 1], "f2": f2([1.0, 0.0])},
        {"type": "traction", "from": [0, 1], "to": [1, 1], "f2": f2([0.0, 1.0])},
        {"type": "traction", "from": [0, 0], "to": [1, 0], "f2": f2([0.0, -1.0])},
    ]);
    if !damage {
        doc.as_object_mut().unwrap().remove("damage");
    }
    scene::validate(&doc).unwrap()
}

/// w = (0.3x + 0.1y, −0.2x + 0.5y) at the nodes, and its constant strain.
fn linear_velocity(mesh: &Mesh<2>) -> (Vec<f64>, Tensor<2>) {
    let w = mesh
        .nodes
        .iter()
        .flat_map(|p| [0.3 * p[0] + 0.1 * p[1], -0.2 * p[0] + 0.5 * p[1]])
        .collect();
    (w, Tensor::<2>::new(0.3, -0.05, -0.05, 0.5))
}

struct Patch {
    problem: Problem,
    mesh: Mesh<2>,
    geo: Geometry<2>,
    w: Vec<f64>,
}

fn patch(damage: bool) -> Patch {
    let mesh = Mesh::rectangle(1.0, 1.0, 4, 4, crate::mesh::MeshPattern::Diagonal);
    let (w, eps) = linear_velocity(&mesh);
    let material = patch_problem(&Tensor::<2>::zeros(), damage).material;
    let sigma = viscous_stress(&material.viscosity, &eps);
    let problem = patch_problem(&sigma, damage);
    let mut mesh = mesh;
    let supports: Vec<_> = problem.boundary.iter().map(|p| p.support.clone()).collect();
    mesh.tag_boundary(&supports).unwrap();
    let geo = Geometry::new(&mesh);
    Patch {
        problem,
        mesh,
        geo,
        w,
    }
}

impl Patch {
    /// The estimate of a step from u_{n−1} = (s x, 0), whose strain is diag(s, 0) on every
    /// cell.
    fn estimate(&self, w: &[f64], s: f64, zeta_prev: &[f64], zeta: &[f64]) -> StepEstimate {
        let b = CellTensors::zeros(self.mesh.n_cells());
        let u_prev: Vec<f64> = self
            .mesh
            .nodes
            .iter()
            .flat_map(|p| [s * p[0], 0.0])
            .collect();
        let data = StepData {
            t: 0.25,
            k: 0.25,
            m_a: 4.0,
            w,
            w_prev: None,
            b: &b,
            u_prev: &u_prev,
            zeta_prev,
            zeta,
        };
        Estimator::new(&self.problem, &self.mesh, &self.geo).step(
            &self.problem,
            &self.mesh,
            &self.geo,
            &data,
        )
    }
}

#[test]
fn a_linear_velocity_with_its_own_tractions_has_no_velocity_residual() {
    let p = patch(false);
    let nc = p.mesh.n_cells();
    let e = p.estimate(&p.w, 0.0, &[], &[]);
    let v = e.parts.velocity;
    assert!(
        v.element == 0.0 && v.friction == 0.0 && v.time == 0.0,
        "{v:?}"
    );
    assert!(v.jump < 1e-14 && v.traction < 1e-14, "{v:?}");
    assert!(e.parts.damage.is_none());
    assert_eq!(e.cells.len(), nc);
}

#[test]
fn a_perturbed_node_gives_jumps_linear_in_the_perturbation() {
    let p = patch(false);
    // An interior node: (0.5, 0.5) is node 2·5 + 2 of the 5 × 5 lattice.
    let node = 12;
    assert_eq!(p.mesh.nodes[node], [0.5, 0.5]);
    let bump = |d: f64| {
        let mut w = p.w.clone();
        w[2 * node] += d;
        p.estimate(&w, 0.0, &[], &[])
    };
    let (one, two) = (bump(1e-3), bump(2e-3));
    assert!(one.parts.velocity.jump > 1e-6);
    let ratio = two.parts.velocity.jump / one.parts.velocity.jump;
    assert!((ratio - 2.0).abs() < 1e-9, "{ratio}");
    // Only the cells around the node (and their facet neighbours) see it.
    let touched = one.cells.iter().filter(|c| **c > 1e-12).count();
    let around = p.mesh.cells().filter(|c| c.contains(&node)).count();
    assert!(
        touched >= around && touched < p.mesh.n_cells(),
        "{touched} of {}",
        p.mesh.n_cells()
    );
}

#[test]
fn damage_residual_vanishes_at_rest_and_is_masked_by_the_obstacle() {
    let p = patch(true);
    let nn = p.mesh.n_nodes();
    let ones = vec![1.0; nn];
    // ζ ≡ 1 with no strain: φ = 0, nothing moves.
    let e = p.estimate(&p.w, 0.0, &ones, &ones);
    assert_eq!(e.parts.damage.unwrap().total, 0.0);
    // With strain φ < 0 pulls ζ = 1 down: the residual is not absorbed at the upper bound.
    let e = p.estimate(&p.w, 0.5, &ones, &ones);
    let d = e.parts.damage.unwrap();
    // r = φ = −b |ε|² = −20 · 0.25 = −5 everywhere: ‖r‖² = 25 on the unit square, and
    // Σ h_T² |T| r² / κ with h_T = √2/4 on every cell.
    let expected = (2.0 / 16.0 * 25.0 / 0.5f64).sqrt();
    assert!((d.element - expected).abs() < 1e-12 * expected, "{d:?}");
    assert!(d.jump == 0.0 && d.time == 0.0);
    // At ζ ≡ 0 (φ reads ζ* = 0.2): φ = 8 − 5 = 3 pushes ζ up, which the lower bound does
    // not take up; a strain of 1 gives φ = 8 − 20 < 0, which it does.
    let zeros = vec![0.0; nn];
    let e = p.estimate(&p.w, 0.5, &zeros, &zeros);
    let expected = (2.0 / 16.0 * 9.0 / 0.5f64).sqrt();
    let d = e.parts.damage.unwrap();
    assert!((d.element - expected).abs() < 1e-12 * expected, "{d:?}");
    let e = p.estimate(&p.w, 1.0, &zeros, &zeros);
    assert_eq!(e.parts.damage.unwrap().element, 0.0);
}

#[test]
fn the_friction_residual_is_the_distance_to_the_subdifferential() {
    let law = FrictionLaw::Tresca { g: 2.0 };
    // Sticking: inside the ball nothing, outside the excess.
    assert_eq!(friction_residual(&law, &[1.0, -1.0], &[0.0, 0.0]), 0.0);
    assert!((friction_residual(&law, &[3.0, 4.0], &[0.0, 0.0]) - 3.0).abs() < 1e-15);
    // Slipping along +x: −σ_τ must be 2 e_x.
    assert_eq!(friction_residual(&law, &[-2.0, 0.0], &[0.5, 0.0]), 0.0);
    assert!((friction_residual(&law, &[2.0, 0.0], &[0.5, 0.0]) - 4.0).abs() < 1e-15);
    // Slip weakening: the bound at the slip speed.
    let sw = FrictionLaw::SlipWeakening {
        mu0: 2.0,
        mu1: 1.0,
        alpha: 1.0,
    };
    let mu = 1.0 + (-1.0f64).exp();
    assert!(friction_residual(&sw, &[-mu, 0.0, 0.0], &[0.0, 1.0, 0.0]) > 0.0);
    assert!(friction_residual(&sw, &[0.0, -mu, 0.0], &[0.0, 1.0, 0.0]) < 1e-15);
}

#[test]
fn the_obstacle_takes_up_only_the_sign_it_can() {
    assert_eq!(obstacle_residual(-3.0, 0.0), 0.0);
    assert_eq!(obstacle_residual(3.0, 0.0), 3.0);
    assert_eq!(obstacle_residual(3.0, 1.0), 0.0);
    assert_eq!(obstacle_residual(-3.0, 1.0), -3.0);
    assert_eq!(obstacle_residual(-3.0, 0.5), -3.0);
}
