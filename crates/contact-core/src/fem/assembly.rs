//! Global matrices of the scheme, assembled once per job:
//! - the velocity operator (A ε(w), ε(v)) on the free DOFs (constant in time: A does not
//!   depend on damage), factored once;
//! - the P1 mass M and stiffness (Laplacian) K of the damage equation (3.10).

use super::{DofMap, Geometry, Slot};
use crate::linalg::Csr;
use crate::mesh::Mesh;

/// (A ε(w), ε(v)) with A(τ) = 2η τ + ξ tr(τ) I on the free DOFs (3.13):
/// K[(a,c),(b,d)] = |T| [η (δ_cd ∇ψ_a·∇ψ_b + ∂_d ψ_a ∂_c ψ_b) + ξ ∂_c ψ_a ∂_d ψ_b].
/// With η = 1/2, ξ = 0 it is the Gram matrix of the V-norm ‖ε(·)‖_L2.
pub fn viscous_stiffness(mesh: &Mesh, geo: &Geometry, dofs: &DofMap, eta: f64, xi: f64) -> Csr {
    let n = dofs.n_free();
    let mut t = Vec::with_capacity(mesh.triangles.len() * 36);
    for (e, tri) in mesh.triangles.iter().enumerate() {
        let (g, area) = (&geo.grads[e], geo.area[e]);
        for a in 0..3 {
            for c in 0..2 {
                let Slot::Free(i) = dofs.slot[2 * tri[a] + c] else {
                    continue;
                };
                for b in 0..3 {
                    let gab = g[a][0] * g[b][0] + g[a][1] * g[b][1];
                    for d in 0..2 {
                        let Slot::Free(j) = dofs.slot[2 * tri[b] + d] else {
                            continue;
                        };
                        let delta = if c == d { gab } else { 0.0 };
                        let v = area * (eta * (delta + g[a][d] * g[b][c]) + xi * g[a][c] * g[b][d]);
                        t.push((i, j, v));
                    }
                }
            }
        }
    }
    Csr::from_triplets(n, n, t)
}

/// Consistent P1 mass matrix M_ab = ∫ ψ_a ψ_b = |T|/12 (1 + δ_ab).
pub fn mass(mesh: &Mesh, geo: &Geometry) -> Csr {
    scalar_matrix(mesh, |e, a, b| {
        geo.area[e] / 12.0 * if a == b { 2.0 } else { 1.0 }
    })
}

/// P1 stiffness (Laplacian) K_ab = ∫ ∇ψ_a·∇ψ_b.
pub fn laplacian(mesh: &Mesh, geo: &Geometry) -> Csr {
    scalar_matrix(mesh, |e, a, b| {
        let g = &geo.grads[e];
        geo.area[e] * (g[a][0] * g[b][0] + g[a][1] * g[b][1])
    })
}

fn scalar_matrix(mesh: &Mesh, entry: impl Fn(usize, usize, usize) -> f64) -> Csr {
    let n = mesh.n_nodes();
    let mut t = Vec::with_capacity(mesh.triangles.len() * 9);
    for (e, tri) in mesh.triangles.iter().enumerate() {
        for a in 0..3 {
            for b in 0..3 {
                t.push((tri[a], tri[b], entry(e, a, b)));
            }
        }
    }
    Csr::from_triplets(n, n, t)
}

/// a·x + b·y for two matrices with the same pattern (M/k + κK of (3.10)).
pub fn combine(a: f64, x: &Csr, b: f64, y: &Csr) -> Csr {
    assert_eq!(x.indices, y.indices, "patterns differ");
    let mut out = x.clone();
    for (o, v) in out.values.iter_mut().zip(&y.values) {
        *o = a * *o + b * v;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::problem::MeshPattern;

    fn meshes() -> Vec<Mesh> {
        [
            MeshPattern::Diagonal,
            MeshPattern::AntiDiagonal,
            MeshPattern::Cross,
        ]
        .into_iter()
        .map(|p| Mesh::rectangle(2.0, 1.0, 6, 3, p))
        .collect()
    }

    #[test]
    fn rigid_body_modes_are_in_the_kernel() {
        for mesh in meshes() {
            let geo = Geometry::new(&mesh);
            let dofs = DofMap::all_free(&mesh);
            let k = viscous_stiffness(&mesh, &geo, &dofs, 2.0, 3.0);
            let n = dofs.n_free();
            // Translations in x and y, and the infinitesimal rotation (−y, x).
            let modes: [fn([f64; 2]) -> [f64; 2]; 3] =
                [|_| [1.0, 0.0], |_| [0.0, 1.0], |p| [-p[1], p[0]]];
            for m in modes {
                let v: Vec<f64> = mesh.nodes.iter().flat_map(|&p| m(p)).collect();
                let mut r = vec![0.0; n];
                k.mul_vec(&v, &mut r);
                let scale = k.values.iter().fold(0.0f64, |s, x| s.max(x.abs()));
                assert!(
                    r.iter().all(|x| x.abs() < 1e-12 * scale),
                    "rigid mode not in kernel"
                );
            }
        }
    }

    #[test]
    fn patch_test_linear_displacement() {
        // u = (0.1x + 0.3y, −0.2x + 0.05y): constant strain, so the interior residual vanishes
        // and the boundary residual equals ∫_∂Ω σν·ψ.  We check that the energy equals |Ω| σ:ε.
        for mesh in meshes() {
            let geo = Geometry::new(&mesh);
            let dofs = DofMap::all_free(&mesh);
            let (eta, xi) = (2.0, 3.0);
            let k = viscous_stiffness(&mesh, &geo, &dofs, eta, xi);
            let u: Vec<f64> = mesh
                .nodes
                .iter()
                .flat_map(|p| [0.1 * p[0] + 0.3 * p[1], -0.2 * p[0] + 0.05 * p[1]])
                .collect();
            let mut r = vec![0.0; u.len()];
            k.mul_vec(&u, &mut r);
            for (i, p) in mesh.nodes.iter().enumerate() {
                let interior =
                    p[0] > 1e-12 && p[0] < 2.0 - 1e-12 && p[1] > 1e-12 && p[1] < 1.0 - 1e-12;
                if interior {
                    assert!(r[2 * i].abs() < 1e-12 && r[2 * i + 1].abs() < 1e-12);
                }
            }
            let energy: f64 = u.iter().zip(&r).map(|(a, b)| a * b).sum();
            let (exx, eyy, exy) = (0.1, 0.05, 0.5 * (0.3 - 0.2));
            let tr = exx + eyy;
            let sig_eps = 2.0 * eta * (exx * exx + eyy * eyy + 2.0 * exy * exy) + xi * tr * tr;
            assert!((energy - 2.0 * sig_eps).abs() < 1e-12);
            // Each element's strain is the exact one.
            for t in 0..mesh.triangles.len() {
                let e = geo.strain(&mesh, t, &u);
                assert!((e[(0, 0)] - exx).abs() < 1e-13 && (e[(0, 1)] - exy).abs() < 1e-13);
            }
        }
    }

    #[test]
    fn mass_sums_to_area_and_laplacian_kills_constants() {
        for mesh in meshes() {
            let geo = Geometry::new(&mesh);
            let m = mass(&mesh, &geo);
            assert!((m.values.iter().sum::<f64>() - 2.0).abs() < 1e-13);
            let k = laplacian(&mesh, &geo);
            let ones = vec![1.0; mesh.n_nodes()];
            let mut r = vec![0.0; mesh.n_nodes()];
            k.mul_vec(&ones, &mut r);
            assert!(r.iter().all(|x| x.abs() < 1e-12));
            // xᵀ K x = ∫|∇x|² = |Ω| for the linear function x.
            let x: Vec<f64> = mesh.nodes.iter().map(|p| p[0]).collect();
            k.mul_vec(&x, &mut r);
            let e: f64 = x.iter().zip(&r).map(|(a, b)| a * b).sum();
            assert!((e - 2.0).abs() < 1e-12);
        }
    }
}
