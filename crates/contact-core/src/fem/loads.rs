//! Right-hand sides: the external load (f_n, v)_V = ∫_Ω f0·v + ∫_Γ2 f2·v, the explicit
//! elastic term −(B_{n−1}, ε(v)) of (3.13), and the damage source F_{n−1} of (3.10), on
//! triangles (d = 2) and tetrahedra (d = 3); nodal vectors have d components per node,
//! interleaved.
//! Quadratures (docs/src/explanation/numerics.md#quadrature-and-load-vectors): exact for constant data (f0:
//! |T|/(d+1) per vertex; f2: |F|/d per facet vertex), otherwise exact for linear data
//! (cells: edge midpoints on triangles, the 4-point rule on tetrahedra; facets: 2-point Gauss
//! on segments, edge midpoints on triangles).

#![allow(clippy::needless_range_loop)] // Index loops over vertices and components spell out the formulas.

use super::{Geometry, NodeCells};
use crate::laws::Tensor;
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
        let w = geo.measure(e) / (D + 1) as f64;
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
                            out[D * n + c] += wq * geo.measure(e) * l[a] * f[c];
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

/// Adds −(B_T, ε(ψ_a e_c)) = −|T| (B_T ∇ψ_a)_c for per-element stresses B_T = `b(T)` (B
/// symmetric) into `out` (D per node, interleaved): gathered node by node over `cells`
/// ([`NodeCells::gather_cell_values`], B_T formed once per chunk of nodes around T), each
/// node's cells subtracted in cell order, so the same bits as the loop over cells on any
/// thread count.
pub fn add_stress_divergence<const D: usize>(
    cells: &NodeCells,
    geo: &Geometry<D>,
    b: impl Fn(usize) -> Tensor<D> + Sync + Send,
    out: &mut [f64],
) {
    cells.gather_cell_values(out, D, b, |e, s, a, out| {
        let (vol, g) = (geo.measure(e), geo.grad(e, a));
        for c in 0..D {
            let mut v = 0.0;
            for k in 0..D {
                v += s[(c, k)] * g[k];
            }
            out[c] -= vol * v;
        }
    });
}

/// F_i = ∫_Ω φ_T(ζ) ψ_i by the cell rule of [`cell_rule`] (triangles: the 3 edge
/// midpoints, weights |T|/3; tetrahedra: the 4-point rule, weights |T|/4), with ζ
/// interpolated linearly to the points and the strain constant on T
/// (docs/src/explanation/numerics.md#damage-source-vector). `phi(&strain(e), ζ)` is the
/// source on element e at damage value ζ (`strain(e)` is formed once per element and chunk
/// of nodes); `out` has one entry per node.
pub fn damage_source<const D: usize, S>(
    mesh: &Mesh<D>,
    cells: &NodeCells,
    geo: &Geometry<D>,
    zeta: &[f64],
    strain: impl Fn(usize) -> S + Sync + Send,
    phi: impl Fn(&S, f64) -> f64 + Sync + Send,
    out: &mut [f64],
) {
    // The source values at a cell's points (φ reads the cell's strain), formed once per
    // chunk of nodes around it; each node gathers its cells' shares in cell order, point by
    // point: the cell loop's sums bit for bit, whatever the thread count.
    let rule = cell_rule(D);
    let at_points = |e: usize| {
        let cell = mesh.cell(e);
        let s = strain(e);
        let mut f = [0.0; 4];
        for ((l, wq), f) in rule.iter().zip(&mut f) {
            let z: f64 = cell.iter().enumerate().map(|(a, &n)| l[a] * zeta[n]).sum();
            *f = if D == 2 {
                phi(&s, z)
            } else {
                wq * geo.measure(e) * phi(&s, z)
            };
        }
        f
    };
    out.iter_mut().for_each(|v| *v = 0.0);
    cells.gather_cell_values(out, 1, at_points, |e, f, a, out| {
        if D == 2 {
            // Edge p runs from vertex p to vertex p + 1: vertex a lies on edges a and a − 1,
            // taken in increasing p.
            let w = geo.measure(e) / 3.0;
            for (p, f) in f[..3].iter().enumerate() {
                if p == a || (p + 1) % 3 == a {
                    out[0] += 0.5 * w * f;
                }
            }
        } else {
            for ((l, _), f) in rule.iter().zip(f) {
                out[0] += l[a] * f;
            }
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::expr::Expr;
    use crate::fem::CellTensors;
    use crate::linalg::par;
    use crate::problem::{MeshPattern, ScalarField, Segment, Support};

    /// The element loops of [`add_stress_divergence`] and [`damage_source`] cell by cell:
    /// their serial forms.
    fn serial_scatters<const D: usize>(
        mesh: &Mesh<D>,
        geo: &Geometry<D>,
        b: &[Tensor<D>],
        zeta: &[f64],
        phi: impl Fn(usize, f64) -> f64,
    ) -> (Vec<f64>, Vec<f64>) {
        let mut div = vec![0.25; D * mesh.n_nodes()];
        for (e, cell) in mesh.cells().enumerate() {
            for (a, &n) in cell.iter().enumerate() {
                let g = geo.grad(e, a);
                for c in 0..D {
                    let mut v = 0.0;
                    for k in 0..D {
                        v += b[e][(c, k)] * g[k];
                    }
                    div[D * n + c] -= geo.measure(e) * v;
                }
            }
        }
        let rule = cell_rule(D);
        let mut src = vec![0.0; mesh.n_nodes()];
        for (e, cell) in mesh.cells().enumerate() {
            let f: Vec<f64> = rule
                .iter()
                .map(|(l, wq)| {
                    let z: f64 = cell.iter().enumerate().map(|(a, &n)| l[a] * zeta[n]).sum();
                    if D == 2 {
                        phi(e, z)
                    } else {
                        wq * geo.measure(e) * phi(e, z)
                    }
                })
                .collect();
            if D == 2 {
                let w = geo.measure(e) / 3.0;
                for (a, f) in f.iter().enumerate() {
                    let (i, j) = (cell[a], cell[(a + 1) % 3]);
                    src[i] += 0.5 * w * f;
                    src[j] += 0.5 * w * f;
                }
            } else {
                for ((l, _), f) in rule.iter().zip(&f) {
                    for (a, &n) in cell.iter().enumerate() {
                        src[n] += l[a] * f;
                    }
                }
            }
        }
        (div, src)
    }

    /// The gathered scatters on 1, 2 and 4 threads are their serial forms bit for bit, on
    /// data of no common scale per cell and node (another order of the sums would show).
    fn gathers_are_the_cell_loops<const D: usize>(mesh: &Mesh<D>) {
        use crate::linalg::par::Threads;
        assert!(
            mesh.n_nodes() > 3 * par::ROW_CHUNK,
            "several chunks of nodes"
        );
        let geo = Geometry::new(mesh);
        let wave = |i: usize, k: usize| ((3 * i + k) as f64).sin() * 10f64.powi((i % 7) as i32 - 3);
        let b: Vec<Tensor<D>> = (0..mesh.n_cells())
            .map(|e| Tensor::<D>::from_fn(|r, c| wave(e, r.min(c) * D + r.max(c))))
            .collect();
        let zeta: Vec<f64> = (0..mesh.n_nodes())
            .map(|i| 0.5 + 0.5 * wave(i, 1).sin())
            .collect();
        let phi = |e: usize, z: f64| (1.0 - z) / (z + 0.1) - wave(e, 2);
        let (div, src) = serial_scatters(mesh, &geo, &b, &zeta, phi);
        let mut stored = CellTensors::zeros(mesh.n_cells());
        stored.fill(|e| b[e]);
        let cells = NodeCells::new(mesh);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        for t in [1, 2, 4] {
            let (mut d, mut f) = (
                vec![0.25; D * mesh.n_nodes()],
                vec![f64::NAN; mesh.n_nodes()],
            );
            Threads::new(t).install(|| {
                add_stress_divergence(&cells, &geo, |e| stored.get(e), &mut d);
                damage_source(mesh, &cells, &geo, &zeta, |e| e, |&e, z| phi(e, z), &mut f);
            });
            assert_eq!(bits(&d), bits(&div), "(B, ε(ψ)) on {t} threads");
            assert_eq!(bits(&f), bits(&src), "F on {t} threads");
        }
    }

    #[test]
    fn gathered_scatters_are_the_cell_loops_bit_for_bit_in_2d() {
        gathers_are_the_cell_loops(&Mesh::rectangle(2.0, 1.0, 14, 9, MeshPattern::Cross));
    }

    #[test]
    fn gathered_scatters_are_the_cell_loops_bit_for_bit_in_3d() {
        gathers_are_the_cell_loops(&Mesh::cuboid(2.0, 1.0, 1.0, 8, 4, 4));
    }

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
