//! Right-hand sides: the external load (f_n, v)_V = ∫_Ω f0·v + ∫_Γ2 f2·v, the explicit
//! elastic term −(B_{n−1}, ε(v)) of (3.13), and the damage source F_{n−1} of (3.10), on
//! triangles (d = 2) and tetrahedra (d = 3); nodal vectors have d components per node,
//! interleaved.
//! Quadratures (docs/src/explanation/numerics.md#quadrature-and-load-vectors): exact for constant data (f0:
//! |T|/(d+1) per vertex; f2: |F|/d per facet vertex), otherwise exact for linear data
//! (cells: edge midpoints on triangles, the 4-point rule on tetrahedra; facets: 2-point Gauss
//! on segments, edge midpoints on triangles).

#![allow(clippy::needless_range_loop)] // Index loops over vertices and components spell out the formulas.

use super::Geometry;
use crate::laws::Tensor;
use crate::linalg::par;
use crate::mesh::Mesh;
use crate::problem::{BoundaryKind, BoundaryPart, VectorField};

/// The 4-point rule on a tetrahedron: barycentric points (a, b, b, b) and permutations,
/// weights |T|/4; exact for quadratics.
const TET_A: f64 = 0.585_410_196_624_968_5; // (5 + 3√5)/20
const TET_B: f64 = 0.138_196_601_125_010_5; // (5 − √5)/20

/// A quadrature rule on the reference simplex of dimension `dim` (2 or 3) for P1 × linear
/// integrands: barycentric coordinates of the points (the first `dim + 1` entries used) and
/// the weight of each point as a fraction of the measure. Triangles: the 3 edge midpoints;
/// tetrahedra: the 4-point rule; segments: 2-point Gauss.
pub fn cell_rule(dim: usize) -> Vec<([f64; 4], f64)> {
    match dim {
        1 => {
            let g = 0.5 / 3f64.sqrt();
            vec![
                ([0.5 + g, 0.5 - g, 0.0, 0.0], 0.5),
                ([0.5 - g, 0.5 + g, 0.0, 0.0], 0.5),
            ]
        }
        2 => (0..3)
            .map(|a| {
                let mut l = [0.0; 4];
                l[a] = 0.5;
                l[(a + 1) % 3] = 0.5;
                (l, 1.0 / 3.0)
            })
            .collect(),
        _ => (0..4)
            .map(|a| {
                let mut l = [TET_B; 4];
                l[a] = TET_A;
                (l, 0.25)
            })
            .collect(),
    }
}

/// The point with barycentric coordinates `l` in the simplex with vertices `v`.
#[inline]
fn point<const D: usize>(v: &[usize], nodes: &[[f64; D]], l: &[f64; 4]) -> [f64; D] {
    std::array::from_fn(|c| v.iter().enumerate().map(|(a, &n)| l[a] * nodes[n][c]).sum())
}

/// Adds ∫_Ω f0(·, t)·ψ_a e_c into `out` (global nodal vector, interleaved).
pub fn add_body_force<const D: usize>(
    mesh: &Mesh<D>,
    geo: &Geometry<D>,
    f0: &VectorField,
    t: f64,
    out: &mut [f64],
) {
    if f0.is_zero() {
        return;
    }
    let constant = f0.is_constant_in_space().then(|| f0.at(&[0.0; D], t));
    let rule = cell_rule(D);
    for (e, cell) in mesh.cells().enumerate() {
        let w = geo.measure[e] / (D + 1) as f64;
        match constant {
            Some(f) => {
                for &n in cell {
                    for c in 0..D {
                        out[D * n + c] += w * f[c];
                    }
                }
            }
            None if D == 2 => {
                // Edge-midpoint rule: ψ_a = 1/2 at the two midpoints of edges through a.
                for a in 0..3 {
                    let (p, q) = (mesh.nodes[cell[a]], mesh.nodes[cell[(a + 1) % 3]]);
                    let m: [f64; D] = std::array::from_fn(|c| 0.5 * (p[c] + q[c]));
                    let f = f0.at(&m, t);
                    for n in [cell[a], cell[(a + 1) % 3]] {
                        for c in 0..D {
                            out[D * n + c] += 0.5 * w * f[c];
                        }
                    }
                }
            }
            None => {
                for (l, wq) in &rule {
                    let f = f0.at(&point(cell, &mesh.nodes, l), t);
                    for (a, &n) in cell.iter().enumerate() {
                        for c in 0..D {
                            out[D * n + c] += wq * geo.measure[e] * l[a] * f[c];
                        }
                    }
                }
            }
        }
    }
}

/// Adds ∫_Γ2 f2(·, t)·ψ_a e_c over every traction facet into `out`.
pub fn add_tractions<const D: usize>(
    mesh: &Mesh<D>,
    parts: &[BoundaryPart],
    t: f64,
    out: &mut [f64],
) {
    let rule = cell_rule(D - 1);
    for e in &mesh.facets {
        let Some(BoundaryKind::Traction(f2)) = e.part.map(|p| &parts[p].kind) else {
            continue;
        };
        if f2.is_zero() {
            continue;
        }
        if D == 2 {
            add_traction_segment(mesh, e, f2, t, out);
            continue;
        }
        if f2.is_constant_in_space() {
            let f = f2.at(&point(&e.nodes, &mesh.nodes, &[1.0 / 3.0; 4]), t);
            for &n in &e.nodes {
                for c in 0..D {
                    out[D * n + c] += e.measure / D as f64 * f[c];
                }
            }
        } else {
            for (l, wq) in &rule {
                let f = f2.at(&point(&e.nodes, &mesh.nodes, l), t);
                for (a, &n) in e.nodes.iter().enumerate() {
                    for c in 0..D {
                        out[D * n + c] += wq * e.measure * l[a] * f[c];
                    }
                }
            }
        }
    }
}

/// A segment's share of [`add_tractions`]: |e|/2 per endpoint for constant data, else
/// 2-point Gauss.
fn add_traction_segment<const D: usize>(
    mesh: &Mesh<D>,
    e: &crate::mesh::Facet<D>,
    f2: &VectorField,
    t: f64,
    out: &mut [f64],
) {
    // 2-point Gauss on [0, 1]: nodes (1 ∓ 1/√3)/2, weights 1/2.
    let g = 0.5 / 3f64.sqrt();
    let (p, q) = (mesh.nodes[e.nodes[0]], mesh.nodes[e.nodes[1]]);
    let at = |s: f64| {
        f2.at(
            &std::array::from_fn::<f64, D, _>(|c| p[c] + s * (q[c] - p[c])),
            t,
        )
    };
    // Contributions to the endpoints [p, q].
    let (fp, fq): ([f64; D], [f64; D]) = if f2.is_constant_in_space() {
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
            std::array::from_fn(|c| w * (f1[c] * (1.0 - s1) + f2v[c] * (1.0 - s2))),
            std::array::from_fn(|c| w * (f1[c] * s1 + f2v[c] * s2)),
        )
    };
    for c in 0..D {
        out[D * e.nodes[0] + c] += fp[c];
        out[D * e.nodes[1] + c] += fq[c];
    }
}

/// A load datum found infinite or NaN at one of its quadrature points.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadFault {
    /// `None`: the body force f0; `Some(p)`: the traction f2 of boundary part p.
    pub part: Option<usize>,
    /// Component (0 = x, 1 = y, 2 = z).
    pub component: usize,
    /// The point (x, y, z; z = 0 in 2D).
    pub at: [f64; 3],
    pub value: f64,
}

/// The first quadrature point (of [`add_body_force`] and [`add_tractions`]) at time t where
/// f0 or an f2 is not finite, if any.
pub fn find_non_finite<const D: usize>(
    mesh: &Mesh<D>,
    f0: &VectorField,
    parts: &[BoundaryPart],
    t: f64,
) -> Option<LoadFault> {
    let check = |f: &VectorField, part: Option<usize>, x: [f64; D]| {
        let v = f.at(&x, t);
        (0..D).find(|&c| !v[c].is_finite()).map(|c| LoadFault {
            part,
            component: c,
            at: std::array::from_fn(|k| if k < D { x[k] } else { 0.0 }),
            value: v[c],
        })
    };
    if !f0.is_zero() {
        if f0.is_constant_in_space() {
            if let Some(fault) = check(f0, None, [0.0; D]) {
                return Some(fault);
            }
        } else {
            let rule = cell_rule(D);
            for cell in mesh.cells() {
                for (l, _) in &rule {
                    if let Some(fault) = check(f0, None, point(cell, &mesh.nodes, l)) {
                        return Some(fault);
                    }
                }
            }
        }
    }
    let centre = [1.0 / D as f64; 4];
    let rule = cell_rule(D - 1);
    for e in &mesh.facets {
        let Some((p, BoundaryKind::Traction(f2))) = e.part.map(|p| (p, &parts[p].kind)) else {
            continue;
        };
        let points: Vec<[f64; 4]> = if f2.is_constant_in_space() {
            vec![centre]
        } else {
            rule.iter().map(|(l, _)| *l).collect()
        };
        for l in &points {
            if let Some(fault) = check(f2, Some(p), point(&e.nodes, &mesh.nodes, l)) {
                return Some(fault);
            }
        }
    }
    None
}

/// Adds −(B_T, ε(ψ_a e_c)) = −|T| (B_T ∇ψ_a)_c for per-element stresses `b` (B symmetric).
pub fn add_stress_divergence<const D: usize>(
    mesh: &Mesh<D>,
    geo: &Geometry<D>,
    b: &[Tensor<D>],
    out: &mut [f64],
) {
    for (e, cell) in mesh.cells().enumerate() {
        let (s, vol) = (&b[e], geo.measure[e]);
        for (a, &n) in cell.iter().enumerate() {
            let g = geo.grads(e)[a];
            for c in 0..D {
                let mut v = 0.0;
                for k in 0..D {
                    v += s[(c, k)] * g[k];
                }
                out[D * n + c] -= vol * v;
            }
        }
    }
}

/// F_i = ∫_Ω φ_T(ζ) ψ_i by the cell rule of [`cell_rule`] (triangles: the 3 edge
/// midpoints, weights |T|/3; tetrahedra: the 4-point rule, weights |T|/4), with ζ
/// interpolated linearly to the points and the strain constant on T
/// (docs/src/explanation/numerics.md#damage-source-vector). `phi(e, ζ)` is the source on element e at
/// damage value ζ.
pub fn damage_source<const D: usize>(
    mesh: &Mesh<D>,
    geo: &Geometry<D>,
    zeta: &[f64],
    phi: impl Fn(usize, f64) -> f64 + Sync,
    out: &mut [f64],
) {
    out.iter_mut().for_each(|v| *v = 0.0);
    // The source values at the points (φ reads the cell's strain) split over the pool's
    // threads in fixed chunks of cells; the scatter then adds them in cell order, so the sum
    // at every node is the serial one, bit for bit, whatever the thread count.
    let rule = cell_rule(D);
    let q = rule.len();
    let mut at_points = vec![0.0; mesh.n_cells() * q];
    par::for_each_chunk_mut(
        &mut at_points,
        q * (par::VECTOR_CHUNK / 4),
        |start, chunk| {
            for (i, f) in chunk.chunks_mut(q).enumerate() {
                let e = start / q + i;
                let cell = mesh.cell(e);
                for ((l, wq), f) in rule.iter().zip(f) {
                    let z: f64 = cell.iter().enumerate().map(|(a, &n)| l[a] * zeta[n]).sum();
                    *f = if D == 2 {
                        phi(e, z)
                    } else {
                        wq * geo.measure[e] * phi(e, z)
                    };
                }
            }
        },
    );
    for (e, (cell, f)) in mesh.cells().zip(at_points.chunks(q)).enumerate() {
        if D == 2 {
            // Edge a's midpoint, between vertices a and a + 1.
            let w = geo.measure[e] / 3.0;
            for (a, f) in f.iter().enumerate() {
                let (i, j) = (cell[a], cell[(a + 1) % 3]);
                out[i] += 0.5 * w * f;
                out[j] += 0.5 * w * f;
            }
        } else {
            for ((l, _), f) in rule.iter().zip(f) {
                for (a, &n) in cell.iter().enumerate() {
                    out[n] += l[a] * f;
                }
            }
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
        let fx = VectorField::plane(
            ScalarField::Expr(Expr::parse("x").unwrap()),
            ScalarField::Const(0.0),
        );
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
            kind: BoundaryKind::Traction(VectorField::plane(
                ScalarField::Expr(Expr::parse("y").unwrap()),
                ScalarField::Const(1.0),
            )),
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
