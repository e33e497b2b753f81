//! Interpolation of a P1 field from a coarse mesh onto a finer nested one
//! (docs/src/explanation/numerics.md#nesting-and-prolongation): the meshes of h and h/2 are nested, so this
//! is exact for P1 fields. Used by convergence studies and error estimates to compare a
//! coarse solution with a finer one on the fine mesh.
//!
//! Nested pairs recognised, in any dimension D:
//! - a mesh and its red refinements (the same mesh as given, refined more often; [`Nesting`];
//!   also a generated rectangle or box and its red refinements): coarse nodes keep their
//!   values, each new node takes the mean of its edge's ends;
//! - two structured rectangles ([`Grid`]) of one diagonal pattern, the fine cell counts
//!   multiples of the coarse ones: the value in the coarse triangle containing the fine node;
//! - two structured boxes ([`Lattice`]) of one size, the fine cell counts multiples of the
//!   coarse ones: the value in the coarse Kuhn tetrahedron containing the fine node.
//!
//! On structured meshes the containing cell and the barycentric weights come from integer
//! lattice indices, so nested nodes are hit exactly and ties on shared faces cannot go wrong
//! (the P1 field is continuous there).

use crate::mesh::cuboid::{kuhn_path_index, KUHN_PATHS};
use crate::mesh::{Grid, Lattice, Mesh, MeshPattern, Nesting};

/// Values at the fine mesh's nodes of the P1 field with nodal values `coarse_values`
/// (`comps` values per node, interleaved; length comps·coarse.n_nodes()) on `coarse`:
/// comps·fine.n_nodes() values, interleaved the same way. None unless the pair is nested as
/// the module doc lists (the "cross" pattern is not supported).
///
/// For boxes whose fine cell counts are the coarse ones times one ratio r in every axis
/// (boxes of h and h/r), the result is the coarse field itself. With different ratios per
/// axis the Kuhn split is not nested, and the result is the coarse field's interpolant at
/// the fine nodes.
pub fn prolongate<const D: usize>(
    coarse: &Mesh<D>,
    coarse_values: &[f64],
    comps: usize,
    fine: &Mesh<D>,
) -> Option<Vec<f64>> {
    debug_assert_eq!(coarse_values.len(), comps * coarse.n_nodes());
    if let Some(levels) = refinements(coarse, fine) {
        let mut v = coarse_values.to_vec();
        for nest in levels {
            v = refined(nest, &v, comps);
        }
        return Some(v);
    }
    if let Some((c, f)) = nested_grids(coarse, fine) {
        return Some(grid_values(&c, &f, coarse_values, comps));
    }
    let (c, f) = nested_lattices(coarse, fine)?;
    Some(lattice_values(&c, &f, coarse_values, comps))
}

/// Rectangles: the fine nodes' values, in the fine node order (see [`Mesh::rectangle`]).
fn grid_values(coarse: &Grid, fine: &Grid, coarse_values: &[f64], comps: usize) -> Vec<f64> {
    let mut out = Vec::with_capacity((fine.nx + 1) * (fine.ny + 1) * comps);
    grid_stencils(coarse, fine, |w| {
        interpolate(w, coarse_values, comps, &mut out)
    });
    out
}

/// Boxes: the fine nodes' values, in the fine node order (see [`Mesh::cuboid`]).
fn lattice_values(
    coarse: &Lattice,
    fine: &Lattice,
    coarse_values: &[f64],
    comps: usize,
) -> Vec<f64> {
    let [fx, fy, fz] = fine.cells;
    let mut out = Vec::with_capacity((fx + 1) * (fy + 1) * (fz + 1) * comps);
    lattice_stencils(coarse, fine, |w| {
        interpolate(w, coarse_values, comps, &mut out)
    });
    out
}

/// Appends Σ w_n v_n per component for one fine node's stencil.
fn interpolate(stencil: &[(usize, f64)], coarse_values: &[f64], comps: usize, out: &mut Vec<f64>) {
    for c in 0..comps {
        out.push(
            stencil
                .iter()
                .map(|&(n, wt)| wt * coarse_values[comps * n + c])
                .sum(),
        );
    }
}

/// Rectangles: visits the P1 interpolation stencil (coarse node, barycentric weight) of
/// every fine node, in the fine node order; the three weights of the coarse triangle that
/// contains the node, zeros included, computed from integer indices so nested nodes are hit
/// exactly. The "cross" pattern is not nested and not supported.
pub fn grid_stencils(coarse: &Grid, fine: &Grid, mut visit: impl FnMut(&[(usize, f64)])) {
    let (rx, ry) = (fine.nx / coarse.nx, fine.ny / coarse.ny);
    let cgrid = |i: usize, j: usize| j * (coarse.nx + 1) + i;
    for j in 0..=fine.ny {
        for i in 0..=fine.nx {
            // Coarse cell containing the fine node, and local coordinates (s, t) in [0, 1]².
            let (ci, cj) = ((i / rx).min(coarse.nx - 1), (j / ry).min(coarse.ny - 1));
            let s = (i - ci * rx) as f64 / rx as f64;
            let t = (j - cj * ry) as f64 / ry as f64;
            let (v00, v10, v11, v01) = (
                cgrid(ci, cj),
                cgrid(ci + 1, cj),
                cgrid(ci + 1, cj + 1),
                cgrid(ci, cj + 1),
            );
            // Barycentric weights in the triangle of the cell that contains (s, t).
            let w: [(usize, f64); 3] = match coarse.pattern {
                MeshPattern::Diagonal if t <= s => [(v00, 1.0 - s), (v10, s - t), (v11, t)],
                MeshPattern::Diagonal => [(v00, 1.0 - t), (v11, s), (v01, t - s)],
                _ if s + t <= 1.0 => [(v00, 1.0 - s - t), (v10, s), (v01, t)],
                _ => [(v10, 1.0 - t), (v11, s + t - 1.0), (v01, 1.0 - s)],
            };
            visit(&w);
        }
    }
}

/// Boxes: visits the P1 interpolation stencil of every fine node, in the fine node order
/// (see [`Mesh::cuboid`]); the four weights of the containing Kuhn tetrahedron, zeros
/// included.
///
/// With (s_a ≥ s_b ≥ s_c) the fine node's local coordinates in its coarse cube sorted
/// descending, the node lies in the Kuhn tetrahedron of the path (a, b, c), whose vertices
/// v000, v000 + e_a, v000 + e_a + e_b, v111 have the barycentric weights 1 − s_a, s_a − s_b,
/// s_b − s_c, s_c. The coordinates are kept as integers over the common denominator
/// rx·ry·rz, so the order and the ties are exact.
pub fn lattice_stencils(coarse: &Lattice, fine: &Lattice, mut visit: impl FnMut(&[(usize, f64)])) {
    let [cx, cy, _] = coarse.cells;
    let r: [usize; 3] = std::array::from_fn(|a| fine.cells[a] / coarse.cells[a]);
    let den = r[0] * r[1] * r[2];
    let cnode = |c: [usize; 3]| c[0] + (cx + 1) * (c[1] + (cy + 1) * c[2]);
    let step = [1, cx + 1, (cx + 1) * (cy + 1)];
    let [fx, fy, fz] = fine.cells;
    for k in 0..=fz {
        for j in 0..=fy {
            for i in 0..=fx {
                let idx = [i, j, k];
                let cell: [usize; 3] =
                    std::array::from_fn(|a| (idx[a] / r[a]).min(coarse.cells[a] - 1));
                // s_a · den, an integer in 0..=den.
                let s: [usize; 3] =
                    std::array::from_fn(|a| (idx[a] - cell[a] * r[a]) * (den / r[a]));
                let mut order = [0, 1, 2];
                order.sort_by(|&a, &b| s[b].cmp(&s[a]));
                let [a, b, c] = order;
                let v0 = cnode(cell);
                let v1 = v0 + step[a];
                let v2 = v1 + step[b];
                let v3 = v0 + step[0] + step[1] + step[2];
                let w = |num: usize| num as f64 / den as f64;
                visit(&[
                    (v0, w(den - s[a])),
                    (v1, w(s[a] - s[b])),
                    (v2, w(s[b] - s[c])),
                    (v3, w(s[c])),
                ]);
            }
        }
    }
}

/// The grids of two structured meshes of one rectangle whose cells nest (same diagonal
/// pattern, fine cell counts multiples of the coarse ones).
fn nested_grids<const D: usize>(coarse: &Mesh<D>, fine: &Mesh<D>) -> Option<(Grid, Grid)> {
    let (c, f) = (coarse.grid?, fine.grid?);
    let nested = c.pattern == f.pattern
        && c.pattern != MeshPattern::Cross
        && f.nx % c.nx == 0
        && f.ny % c.ny == 0;
    nested.then_some((c, f))
}

/// The lattices of two structured boxes of one size, the fine cell counts multiples of the
/// coarse ones.
fn nested_lattices<const D: usize>(coarse: &Mesh<D>, fine: &Mesh<D>) -> Option<(Lattice, Lattice)> {
    let (c, f) = (coarse.lattice?, fine.lattice?);
    let nested = c.size == f.size && (0..3).all(|a| f.cells[a] % c.cells[a] == 0);
    nested.then_some((c, f))
}

/// The red refinements that lead from `coarse` to `fine`, when `fine` was made from
/// `coarse` by refining (the same mesh as given, refined fewer times).
fn refinements<'a, const D: usize>(coarse: &Mesh<D>, fine: &'a Mesh<D>) -> Option<&'a [Nesting]> {
    let (lc, lf) = (coarse.nesting.len(), fine.nesting.len());
    let structured = |m: &Mesh<D>| m.grid.is_some() || m.lattice.is_some();
    // Two generated meshes are compared through their lattices (equal counts do not make
    // them the same mesh); a generated mesh and its refinements go through the nesting.
    if structured(fine) || lf < lc || (structured(coarse) && lf == lc) {
        return None;
    }
    let same_start =
        coarse.nesting.iter().zip(&fine.nesting).all(|(a, b)| {
            a.coarse_nodes == b.coarse_nodes && a.midpoints.len() == b.midpoints.len()
        });
    let next_is_coarse = match fine.nesting.get(lc) {
        Some(n) => n.coarse_nodes == coarse.n_nodes(),
        None => fine.n_nodes() == coarse.n_nodes(),
    };
    // Each red refinement makes 2^D children per cell, the first of which keeps its parent's
    // vertex 0; refinement keeps the coarse nodes first. Checking these (exactly: refinement
    // copies the coordinates) tells a refinement from another mesh with the same counts.
    let per = 1usize << (D * (lf - lc));
    let counts = same_start && next_is_coarse && fine.n_cells() == coarse.n_cells() * per;
    let same_nodes = || fine.nodes.get(..coarse.n_nodes()) == Some(&coarse.nodes[..]);
    let same_cells = || (0..coarse.n_cells()).all(|c| fine.cell(per * c)[0] == coarse.cell(c)[0]);
    (counts && same_nodes() && same_cells()).then(|| &fine.nesting[lc..])
}

/// A red refinement's nodal values: coarse nodes keep theirs, midpoints take the mean.
fn refined(nest: &Nesting, coarse_values: &[f64], comps: usize) -> Vec<f64> {
    let mut out = coarse_values[..nest.coarse_nodes * comps].to_vec();
    // The ends of a midpoint are coarse nodes (red refinement) or, after bisections,
    // midpoints made before it: both are in `out` already.
    for &[a, b] in &nest.midpoints {
        for c in 0..comps {
            out.push(0.5 * (out[comps * a + c] + out[comps * b + c]));
        }
    }
    out
}

/// For every cell of `fine`, the cell of `coarse` containing it (nested pairs as for
/// [`prolongate`]; fine.n_cells() indices). On a fine cell T, the interpolant of a coarse
/// P1 field is the coarse field itself, so ε(I v)|_T = ε(v)|_parent(T): strain errors need
/// no interpolation at all.
///
/// None for pairs that are not nested; structured boxes are nested only when the fine cell
/// counts are the coarse ones times one ratio in every axis.
pub fn parent_cells<const D: usize>(coarse: &Mesh<D>, fine: &Mesh<D>) -> Option<Vec<u32>> {
    if let Some(levels) = refinements(coarse, fine) {
        let per = 1usize << (D * levels.len());
        return Some((0..fine.n_cells()).map(|t| (t / per) as u32).collect());
    }
    if let Some((c, f)) = nested_grids(coarse, fine) {
        return Some(grid_parents(&c, &f));
    }
    let (c, f) = nested_lattices(coarse, fine)?;
    lattice_parents(&c, &f)
}

/// Rectangles: the parent of every fine triangle, in the fine cell order.
fn grid_parents(coarse: &Grid, fine: &Grid) -> Vec<u32> {
    let (rx, ry) = (fine.nx / coarse.nx, fine.ny / coarse.ny);
    // Centroids of a cell's two triangles, in thirds of the cell (see Mesh::rectangle).
    let centroids: [[usize; 2]; 2] = match fine.pattern {
        MeshPattern::Diagonal => [[2, 1], [1, 2]],
        _ => [[1, 1], [2, 2]],
    };
    let mut parents = Vec::with_capacity(2 * fine.nx * fine.ny);
    for j in 0..fine.ny {
        for i in 0..fine.nx {
            let (ci, cj) = (i / rx, j / ry);
            for c in centroids {
                // Position in the coarse cell, in units of 1/(3 r): integers, so no ties.
                let s = 3 * (i - ci * rx) + c[0];
                let t = 3 * (j - cj * ry) + c[1];
                let (sx, ty) = (s * ry, t * rx);
                let second = match coarse.pattern {
                    MeshPattern::Diagonal => ty > sx,
                    _ => sx + ty > 3 * rx * ry,
                };
                parents.push((2 * (cj * coarse.nx + ci) + usize::from(second)) as u32);
            }
        }
    }
    parents
}

/// Boxes: the parent of every fine tetrahedron, in the fine cell order; None unless the
/// ratio of the cell counts is the same in every axis.
///
/// The centroid of the Kuhn tetrahedron of path (a, b, c) has the local coordinates 3/4,
/// 2/4 and 1/4 along a, b and c in its cube. In the coarse cube, in units of 1/(4r), they are
/// the integers 4·d + q (d the fine cube's offset, q ∈ {1, 2, 3}), all distinct, and their
/// descending order is the coarse path whose tetrahedron contains the fine one.
fn lattice_parents(coarse: &Lattice, fine: &Lattice) -> Option<Vec<u32>> {
    let r = fine.cells[0] / coarse.cells[0];
    if (0..3).any(|a| fine.cells[a] != r * coarse.cells[a]) {
        return None;
    }
    let [cx, cy, _] = coarse.cells;
    let [fx, fy, fz] = fine.cells;
    let mut parents = Vec::with_capacity(6 * fx * fy * fz);
    for k in 0..fz {
        for j in 0..fy {
            for i in 0..fx {
                let idx = [i, j, k];
                let cell: [usize; 3] = std::array::from_fn(|a| idx[a] / r);
                let cube = cell[0] + cx * (cell[1] + cy * cell[2]);
                for path in KUHN_PATHS {
                    let mut t = [0; 3];
                    for (q, &axis) in path.iter().enumerate() {
                        t[axis] = 4 * (idx[axis] - cell[axis] * r) + 3 - q;
                    }
                    let mut order = [0, 1, 2];
                    order.sort_by(|&a, &b| t[b].cmp(&t[a]));
                    parents.push((6 * cube + kuhn_path_index(order)) as u32);
                }
            }
        }
    }
    Some(parents)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_for_p1_fields() {
        for pattern in [MeshPattern::Diagonal, MeshPattern::AntiDiagonal] {
            let coarse = Mesh::rectangle(2.0, 1.0, 4, 2, pattern);
            let fine = Mesh::rectangle(2.0, 1.0, 16, 8, pattern);
            // A linear function is reproduced exactly.
            let lin = |p: [f64; 2]| [1.0 + 2.0 * p[0] - 3.0 * p[1], -0.5 * p[0] + p[1]];
            let cv: Vec<f64> = coarse.nodes.iter().flat_map(|&p| lin(p)).collect();
            let fv = prolongate(&coarse, &cv, 2, &fine).unwrap();
            for (n, &p) in fine.nodes.iter().enumerate() {
                let e = lin(p);
                assert!((fv[2 * n] - e[0]).abs() < 1e-13 && (fv[2 * n + 1] - e[1]).abs() < 1e-13);
            }
            // A piecewise-linear (non-linear) coarse field: values at coarse nodes are kept and
            // each fine node lies on the coarse triangle's plane (checked via the midpoint rule).
            let cz: Vec<f64> = (0..coarse.n_nodes())
                .map(|i| ((i * 37) % 11) as f64)
                .collect();
            let fz = prolongate(&coarse, &cz, 1, &fine).unwrap();
            for (n, &p) in coarse.nodes.iter().enumerate() {
                let f = fine.nodes.iter().position(|&q| q == p).unwrap();
                assert_eq!(fz[f], cz[n]);
            }
            // Integral of the field is preserved (it is the same function).
            let integral = |m: &Mesh, v: &[f64]| -> f64 {
                (0..m.n_cells())
                    .map(|t| m.area(t) * m.triangle(t).iter().map(|&i| v[i]).sum::<f64>() / 3.0)
                    .sum()
            };
            assert!((integral(&coarse, &cz) - integral(&fine, &fz)).abs() < 1e-12);
        }
    }

    #[test]
    fn parents_contain_their_children_and_carry_the_strain() {
        use crate::fem::Geometry;
        for pattern in [MeshPattern::Diagonal, MeshPattern::AntiDiagonal] {
            let coarse = Mesh::rectangle(2.0, 1.0, 4, 2, pattern);
            let fine = Mesh::rectangle(2.0, 1.0, 12, 6, pattern);
            let parents = parent_cells(&coarse, &fine).unwrap();
            assert_eq!(parents.len(), fine.n_cells());
            for (t, &p) in parents.iter().enumerate() {
                let c = fine.triangle(t).iter().fold([0.0; 2], |a, &n| {
                    [a[0] + fine.nodes[n][0] / 3.0, a[1] + fine.nodes[n][1] / 3.0]
                });
                let q = coarse.triangle(p as usize).map(|n| coarse.nodes[n]);
                let cross = |a: [f64; 2], b: [f64; 2]| {
                    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
                };
                let sides = [cross(q[0], q[1]), cross(q[1], q[2]), cross(q[2], q[0])];
                assert!(
                    sides.iter().all(|&x| x > 0.0),
                    "{pattern:?}: triangle {t} not in {p}"
                );
            }
            // ε of the interpolant on a fine triangle = ε of the coarse field on its parent.
            let cv: Vec<f64> = (0..2 * coarse.n_nodes())
                .map(|i| ((i * 7) % 5) as f64)
                .collect();
            let fv = prolongate(&coarse, &cv, 2, &fine).unwrap();
            let (gc, gf) = (Geometry::new(&coarse), Geometry::new(&fine));
            for (t, &p) in parents.iter().enumerate() {
                let d = gf.strain(&fine, t, &fv) - gc.strain(&coarse, p as usize, &cv);
                assert!(d.norm() < 1e-12, "{pattern:?} {t}: {d}");
            }
        }
        let a = Mesh::rectangle(1.0, 1.0, 3, 3, MeshPattern::Diagonal);
        assert!(
            parent_cells(&a, &Mesh::rectangle(1.0, 1.0, 4, 4, MeshPattern::Diagonal)).is_none()
        );
    }

    /// A deterministic field of "random" values in [-1, 1).
    fn noise(n: usize, seed: u64) -> Vec<f64> {
        let mut x = seed;
        (0..n)
            .map(|_| {
                x = x
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (x >> 11) as f64 / (1u64 << 52) as f64 - 1.0
            })
            .collect()
    }

    /// The value at p of the P1 field v on `mesh` (one component), found by a search for the
    /// tetrahedron containing p (barycentric coordinates ≥ −1e-12).
    fn evaluate(mesh: &Mesh<3>, v: &[f64], p: [f64; 3]) -> f64 {
        use crate::mesh::signed_measure;
        for cell in mesh.cells() {
            let x: [[f64; 3]; 4] = std::array::from_fn(|a| mesh.nodes[cell[a]]);
            let vol = signed_measure(&x);
            let lam: [f64; 4] = std::array::from_fn(|a| {
                let mut y = x;
                y[a] = p;
                signed_measure(&y) / vol
            });
            if lam.iter().all(|&l| l >= -1e-12) {
                return (0..4).map(|a| lam[a] * v[cell[a]]).sum();
            }
        }
        panic!("{p:?} is in no cell");
    }

    #[test]
    fn boxes_prolongate_exactly() {
        let lin = |p: [f64; 3]| [1.0 + 2.0 * p[0] - 3.0 * p[1] + 0.5 * p[2], p[1] - p[2]];
        for (coarse_n, fine_n) in [
            ([2, 1, 1], [4, 2, 2]),
            ([2, 1, 1], [6, 3, 3]),
            ([2, 2, 1], [4, 6, 3]),
        ] {
            let coarse = Mesh::<3>::cuboid(2.0, 1.0, 1.5, coarse_n[0], coarse_n[1], coarse_n[2]);
            let fine = Mesh::<3>::cuboid(2.0, 1.0, 1.5, fine_n[0], fine_n[1], fine_n[2]);
            let cv: Vec<f64> = coarse.nodes.iter().flat_map(|&p| lin(p)).collect();
            let fv = prolongate(&coarse, &cv, 2, &fine).unwrap();
            for (n, &p) in fine.nodes.iter().enumerate() {
                let e = lin(p);
                assert!((fv[2 * n] - e[0]).abs() < 1e-13 && (fv[2 * n + 1] - e[1]).abs() < 1e-13);
            }
            // A P1 field that is not linear: the coarse field evaluated at the fine nodes.
            let cz = noise(coarse.n_nodes(), 7);
            let fz = prolongate(&coarse, &cz, 1, &fine).unwrap();
            for (n, &p) in fine.nodes.iter().enumerate() {
                let e = evaluate(&coarse, &cz, p);
                assert!(
                    (fz[n] - e).abs() < 1e-13,
                    "{coarse_n:?} → {fine_n:?} node {n}"
                );
            }
        }
        let a = Mesh::<3>::cuboid(1.0, 1.0, 1.0, 2, 2, 2);
        for b in [
            Mesh::<3>::cuboid(1.0, 1.0, 1.0, 3, 4, 4),
            Mesh::<3>::cuboid(1.0, 1.0, 2.0, 4, 4, 4),
        ] {
            assert!(prolongate(&a, &vec![0.0; a.n_nodes()], 1, &b).is_none());
            assert!(parent_cells(&a, &b).is_none());
        }
    }

    #[test]
    fn box_parents_contain_their_children_and_carry_the_strain() {
        use crate::fem::Geometry;
        use crate::mesh::signed_measure;
        let coarse = Mesh::<3>::cuboid(2.0, 1.0, 1.0, 2, 1, 1);
        let fine = Mesh::<3>::cuboid(2.0, 1.0, 1.0, 6, 3, 3);
        let parents = parent_cells(&coarse, &fine).unwrap();
        assert_eq!(parents.len(), fine.n_cells());
        for (t, &p) in parents.iter().enumerate() {
            let c = fine.cell(t).iter().fold([0.0; 3], |s, &n| {
                std::array::from_fn(|a| s[a] + fine.nodes[n][a] / 4.0)
            });
            let x: [[f64; 3]; 4] =
                std::array::from_fn(|a| coarse.nodes[coarse.cell(p as usize)[a]]);
            let vol = signed_measure(&x);
            for a in 0..4 {
                let mut y = x;
                y[a] = c;
                assert!(
                    signed_measure(&y) / vol > 1e-9,
                    "tetrahedron {t} not in {p}"
                );
            }
        }
        let cv = noise(3 * coarse.n_nodes(), 3);
        let fv = prolongate(&coarse, &cv, 3, &fine).unwrap();
        let (gc, gf) = (Geometry::new(&coarse), Geometry::new(&fine));
        for (t, &p) in parents.iter().enumerate() {
            let d = gf.strain(&fine, t, &fv) - gc.strain(&coarse, p as usize, &cv);
            assert!(d.norm() < 1e-12, "{t}: {d}");
        }
        // Different ratios per axis: not nested.
        let skew = Mesh::<3>::cuboid(2.0, 1.0, 1.0, 4, 3, 2);
        assert!(parent_cells(&coarse, &skew).is_none());
    }

    #[test]
    fn bey_refinements_prolongate_exactly() {
        let nodes = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.1, 0.0],
            [0.2, 1.0, 0.1],
            [0.1, 0.3, 1.0],
            [1.1, 1.2, 0.9],
        ];
        let coarse = Mesh::<3>::from_cells(nodes, vec![0, 1, 2, 3, 1, 2, 3, 4]).unwrap();
        let once = coarse.refine();
        let twice = once.refine();
        let cz = noise(coarse.n_nodes(), 5);
        for fine in [&once, &twice] {
            let fz = prolongate(&coarse, &cz, 1, fine).unwrap();
            for (n, &p) in fine.nodes.iter().enumerate() {
                assert!((fz[n] - evaluate(&coarse, &cz, p)).abs() < 1e-13);
            }
            let parents = parent_cells(&coarse, fine).unwrap();
            assert_eq!(parents.len(), fine.n_cells());
        }
        // From the once-refined mesh on, too; and never backwards.
        let mid = prolongate(&coarse, &cz, 1, &once).unwrap();
        assert_eq!(
            prolongate(&once, &mid, 1, &twice),
            prolongate(&coarse, &cz, 1, &twice)
        );
        assert!(prolongate(&twice, &vec![0.0; twice.n_nodes()], 1, &once).is_none());
        assert_eq!(parent_cells(&once, &twice).unwrap()[8 * 5 + 3], 5);
    }

    #[test]
    fn refuses_non_nested() {
        let a = Mesh::rectangle(1.0, 1.0, 3, 3, MeshPattern::Diagonal);
        let b = Mesh::rectangle(1.0, 1.0, 4, 4, MeshPattern::Diagonal);
        assert!(prolongate(&a, &vec![0.0; a.n_nodes()], 1, &b).is_none());
        // Boxes with the same counts of nodes and cells but other shapes.
        let a = Mesh::<3>::cuboid(2.0, 1.0, 1.0, 4, 2, 2);
        let b = Mesh::<3>::cuboid(1.0, 2.0, 1.0, 2, 4, 2);
        assert_eq!((a.n_nodes(), a.n_cells()), (b.n_nodes(), b.n_cells()));
        assert!(prolongate(&a, &vec![0.0; a.n_nodes()], 1, &b).is_none());
        assert!(parent_cells(&a, &b).is_none());
        assert!(prolongate(&a, &vec![0.0; a.n_nodes()], 1, &b.refine()).is_none());
    }

    #[test]
    fn generated_meshes_prolongate_onto_their_red_refinements() {
        let rect = Mesh::rectangle(2.0, 1.0, 4, 2, MeshPattern::AntiDiagonal);
        let fine = rect.refine().refine();
        let cv = noise(rect.n_nodes(), 1);
        let fv = prolongate(&rect, &cv, 1, &fine).unwrap();
        let parents = parent_cells(&rect, &fine).unwrap();
        for (t, &p) in parents.iter().enumerate() {
            // The fine value at a vertex is the coarse field at that point of the parent.
            let q = rect.triangle(p as usize).map(|n| rect.nodes[n]);
            let area = crate::mesh::signed_measure(&q);
            for &n in &fine.triangle(t) {
                let x = fine.nodes[n];
                let lam: [f64; 3] = std::array::from_fn(|a| {
                    let mut y = q;
                    y[a] = x;
                    crate::mesh::signed_measure(&y) / area
                });
                assert!(lam.iter().all(|&l| l > -1e-12), "{t} not in {p}");
                let e: f64 = (0..3)
                    .map(|a| lam[a] * cv[rect.triangle(p as usize)[a]])
                    .sum();
                assert!((fv[n] - e).abs() < 1e-13);
            }
        }
        let cuboid = Mesh::<3>::cuboid(2.0, 1.0, 1.0, 2, 1, 1);
        let fine = cuboid.refine();
        let cz = noise(cuboid.n_nodes(), 2);
        let fz = prolongate(&cuboid, &cz, 1, &fine).unwrap();
        for (n, &p) in fine.nodes.iter().enumerate() {
            assert!((fz[n] - evaluate(&cuboid, &cz, p)).abs() < 1e-13);
        }
        assert_eq!(parent_cells(&cuboid, &fine).unwrap()[8 * 7 + 5], 7);
    }
}
