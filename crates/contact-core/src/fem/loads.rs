//! Right-hand sides: the external load (f_n, v)_V = ∫_Ω f0·v + ∫_Γ2 f2·v, the explicit
//! elastic term −(B_{n−1}, ε(v)) of (3.13), and the damage source F_{n−1} of (3.10).
//! Quadratures (docs/numerics.md#quadrature-and-load-vectors): exact for constant data (f0: |T|/3 per vertex; f2: |e|/2
//! per endpoint), otherwise exact for linear data (edge midpoints on T, 2-point Gauss on e).

use super::Geometry;
use crate::laws::Tensor2;
use crate::mesh::Mesh;
use crate::problem::{BoundaryKind, BoundaryPart, VectorField};

/// Adds ∫_Ω f0(·, t)·ψ_a e_c into `out` (global nodal vector, interleaved).
pub fn add_body_force(mesh: &Mesh, geo: &Geometry, f0: &VectorField, t: f64, out: &mut [f64]) {
    if f0.is_zero() {
        return;
    }
    let constant = f0.is_constant_in_space().then(|| f0.eval(0.0, 0.0, t));
    for (e, tri) in mesh.triangles().iter().enumerate() {
        let w = geo.measure[e] / 3.0;
        match constant {
            Some(f) => {
                for &n in tri {
                    out[2 * n] += w * f[0];
                    out[2 * n + 1] += w * f[1];
                }
            }
            None => {
                // Edge-midpoint rule: ψ_a = 1/2 at the two midpoints of edges through a.
                for a in 0..3 {
                    let (p, q) = (mesh.nodes[tri[a]], mesh.nodes[tri[(a + 1) % 3]]);
                    let f = f0.eval(0.5 * (p[0] + q[0]), 0.5 * (p[1] + q[1]), t);
                    for n in [tri[a], tri[(a + 1) % 3]] {
                        out[2 * n] += 0.5 * w * f[0];
                        out[2 * n + 1] += 0.5 * w * f[1];
                    }
                }
            }
        }
    }
}

/// Adds ∫_Γ2 f2(·, t)·ψ_a e_c over every traction edge into `out`.
pub fn add_tractions(mesh: &Mesh, parts: &[BoundaryPart], t: f64, out: &mut [f64]) {
    // 2-point Gauss on [0, 1]: nodes (1 ∓ 1/√3)/2, weights 1/2.
    let g = 0.5 / 3f64.sqrt();
    for e in &mesh.facets {
        let Some(BoundaryKind::Traction(f2)) = e.part.map(|p| &parts[p].kind) else {
            continue;
        };
        if f2.is_zero() {
            continue;
        }
        let (p, q) = (mesh.nodes[e.nodes[0]], mesh.nodes[e.nodes[1]]);
        let at = |s: f64| f2.eval(p[0] + s * (q[0] - p[0]), p[1] + s * (q[1] - p[1]), t);
        // Contributions to the endpoints [p, q].
        let (fp, fq) = if f2.is_constant_in_space() {
            let f = at(0.5);
            (
                f.map(|v| 0.5 * e.measure * v),
                f.map(|v| 0.5 * e.measure * v),
            )
        } else {
            let (s1, s2) = (0.5 - g, 0.5 + g);
            let (f1, f2v) = (at(s1), at(s2));
            let w = 0.5 * e.measure;
            (
                [0, 1].map(|c| w * (f1[c] * (1.0 - s1) + f2v[c] * (1.0 - s2))),
                [0, 1].map(|c| w * (f1[c] * s1 + f2v[c] * s2)),
            )
        };
        for c in 0..2 {
            out[2 * e.nodes[0] + c] += fp[c];
            out[2 * e.nodes[1] + c] += fq[c];
        }
    }
}

/// A load datum found infinite or NaN at one of its quadrature points.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadFault {
    /// `None`: the body force f0; `Some(p)`: the traction f2 of boundary part p.
    pub part: Option<usize>,
    /// Component (0 = x, 1 = y).
    pub component: usize,
    pub at: [f64; 2],
    pub value: f64,
}

/// The first quadrature point (of [`add_body_force`] and [`add_tractions`]) at time t where
/// f0 or an f2 is not finite, if any.
pub fn find_non_finite(
    mesh: &Mesh,
    f0: &VectorField,
    parts: &[BoundaryPart],
    t: f64,
) -> Option<LoadFault> {
    let check = |f: &VectorField, part: Option<usize>, x: f64, y: f64| {
        let v = f.eval(x, y, t);
        (0..2).find(|&c| !v[c].is_finite()).map(|c| LoadFault {
            part,
            component: c,
            at: [x, y],
            value: v[c],
        })
    };
    if !f0.is_zero() {
        if f0.is_constant_in_space() {
            if let Some(fault) = check(f0, None, 0.0, 0.0) {
                return Some(fault);
            }
        } else {
            for tri in mesh.triangles() {
                for a in 0..3 {
                    let (p, q) = (mesh.nodes[tri[a]], mesh.nodes[tri[(a + 1) % 3]]);
                    if let Some(fault) = check(f0, None, 0.5 * (p[0] + q[0]), 0.5 * (p[1] + q[1])) {
                        return Some(fault);
                    }
                }
            }
        }
    }
    let g = 0.5 / 3f64.sqrt();
    for e in &mesh.facets {
        let Some((p, BoundaryKind::Traction(f2))) = e.part.map(|p| (p, &parts[p].kind)) else {
            continue;
        };
        let (a, b) = (mesh.nodes[e.nodes[0]], mesh.nodes[e.nodes[1]]);
        let points: &[f64] = if f2.is_constant_in_space() {
            &[0.5]
        } else {
            &[0.5 - g, 0.5 + g]
        };
        for &s in points {
            let (x, y) = (a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1]));
            if let Some(fault) = check(f2, Some(p), x, y) {
                return Some(fault);
            }
        }
    }
    None
}

/// Adds −(B_T, ε(ψ_a e_c)) = −|T| (B_T ∇ψ_a)_c for per-element stresses `b` (B symmetric).
pub fn add_stress_divergence(mesh: &Mesh, geo: &Geometry, b: &[Tensor2<f64>], out: &mut [f64]) {
    for (e, tri) in mesh.triangles().iter().enumerate() {
        let (s, area) = (&b[e], geo.measure[e]);
        for (a, &n) in tri.iter().enumerate() {
            let g = geo.grads(e)[a];
            out[2 * n] -= area * (s[(0, 0)] * g[0] + s[(0, 1)] * g[1]);
            out[2 * n + 1] -= area * (s[(1, 0)] * g[0] + s[(1, 1)] * g[1]);
        }
    }
}

/// F_i = ∫_Ω φ_T(ζ) ψ_i by the 3-point edge-midpoint rule (weights |T|/3), with ζ
/// interpolated linearly to the midpoints and the strain constant on T (docs/numerics.md#damage-source-vector).
/// `phi(e, ζ)` is the source on element e at damage value ζ.
pub fn damage_source(
    mesh: &Mesh,
    geo: &Geometry,
    zeta: &[f64],
    phi: impl Fn(usize, f64) -> f64,
    out: &mut [f64],
) {
    out.iter_mut().for_each(|v| *v = 0.0);
    for (e, tri) in mesh.triangles().iter().enumerate() {
        let w = geo.measure[e] / 3.0;
        for a in 0..3 {
            let (i, j) = (tri[a], tri[(a + 1) % 3]);
            let f = phi(e, 0.5 * (zeta[i] + zeta[j]));
            out[i] += 0.5 * w * f;
            out[j] += 0.5 * w * f;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::expr::Expr;
    use crate::problem::{MeshPattern, ScalarField, Segment, Support};

    #[test]
    fn constant_and_linear_loads_integrate_exactly() {
        let mesh = Mesh::rectangle(2.0, 1.0, 4, 2, MeshPattern::Diagonal);
        let geo = Geometry::new(&mesh);
        let mut out = vec![0.0; 2 * mesh.n_nodes()];
        add_body_force(
            &mesh,
            &geo,
            &VectorField::constant([0.0, -0.5]),
            0.0,
            &mut out,
        );
        let fy: f64 = out.iter().skip(1).step_by(2).sum();
        assert!((fy + 1.0).abs() < 1e-14);
        // f0_x = x: ∫ x dΩ = 2 and ∫ x·x dΩ = 8/3 (moment, exact for linear data).
        let fx = VectorField([
            ScalarField::Expr(Expr::parse("x").unwrap()),
            ScalarField::Const(0.0),
        ]);
        out.iter_mut().for_each(|v| *v = 0.0);
        add_body_force(&mesh, &geo, &fx, 0.0, &mut out);
        let total: f64 = out.iter().step_by(2).sum();
        let moment: f64 = (0..mesh.n_nodes())
            .map(|n| out[2 * n] * mesh.nodes[n][0])
            .sum();
        assert!((total - 2.0).abs() < 1e-13 && (moment - 8.0 / 3.0).abs() < 1e-13);

        // Traction f2 = (y, 1) on the right side x = 2: ∫ y dy = 1/2, ∫ 1 = 1.
        let mut m = mesh.clone();
        let parts = vec![BoundaryPart {
            kind: BoundaryKind::Traction(VectorField([
                ScalarField::Expr(Expr::parse("y").unwrap()),
                ScalarField::Const(1.0),
            ])),
            support: Support::Segment(Segment {
                a: [2.0, 0.0],
                b: [2.0, 1.0],
            }),
        }];
        m.tag_boundary(&[parts[0].support.clone()]).unwrap();
        out.iter_mut().for_each(|v| *v = 0.0);
        add_tractions(&m, &parts, 0.0, &mut out);
        let sx: f64 = out.iter().step_by(2).sum();
        let sy: f64 = out.iter().skip(1).step_by(2).sum();
        let first_moment: f64 = (0..m.n_nodes()).map(|n| out[2 * n] * m.nodes[n][1]).sum();
        assert!((sx - 0.5).abs() < 1e-14 && (sy - 1.0).abs() < 1e-14);
        assert!((first_moment - 1.0 / 3.0).abs() < 1e-14);
    }
}
