//! Interpolation of a P1 field from a coarse structured mesh onto a finer nested one
//! (docs/numerics.md#nesting-and-prolongation: meshes of h and h/2 are nested, so this is exact for P1 fields). Used by
//! convergence studies to compare a coarse solution with the reference on the fine mesh.

use crate::mesh::{Grid, Mesh, MeshPattern, Nesting};

/// Values at the fine mesh's nodes of the P1 field with nodal values `coarse_values`
/// (`comps` values per node, interleaved) on `coarse`. Both meshes cover the same rectangle
/// and the coarse cells are unions of fine cells. The "cross" pattern is not supported
/// (returns None), nor are non-nested pairs.
pub fn prolongate(
    coarse: &Mesh,
    coarse_values: &[f64],
    comps: usize,
    fine: &Mesh,
) -> Option<Vec<f64>> {
    if let Some(levels) = refinements(coarse, fine) {
        let mut v = coarse_values.to_vec();
        for nest in levels {
            v = refined(nest, &v, comps);
        }
        return Some(v);
    }
    let (coarse, fine) = nested_grids(coarse, fine)?;
    let (rx, ry) = (fine.nx / coarse.nx, fine.ny / coarse.ny);
    let cgrid = |i: usize, j: usize| j * (coarse.nx + 1) + i;
    let mut out = Vec::with_capacity((fine.nx + 1) * (fine.ny + 1) * comps);
    for j in 0..=fine.ny {
        for i in 0..=fine.nx {
            // Coarse cell containing the fine node, and local coordinates (s, t) in [0, 1]²,
            // computed from integer indices so nested nodes are hit exactly.
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
            for c in 0..comps {
                out.push(
                    w.iter()
                        .map(|&(n, wt)| wt * coarse_values[comps * n + c])
                        .sum(),
                );
            }
        }
    }
    Some(out)
}

/// The grids of two structured meshes of one rectangle whose cells nest (same diagonal
/// pattern, fine cell counts multiples of the coarse ones).
fn nested_grids(coarse: &Mesh, fine: &Mesh) -> Option<(Grid, Grid)> {
    let (c, f) = (coarse.grid?, fine.grid?);
    let nested = c.pattern == f.pattern
        && c.pattern != MeshPattern::Cross
        && f.nx % c.nx == 0
        && f.ny % c.ny == 0;
    nested.then_some((c, f))
}

/// The red refinements that lead from `coarse` to `fine`, when `fine` was made from
/// `coarse` by refining (the same mesh as given, refined fewer times).
fn refinements<'a>(coarse: &Mesh, fine: &'a Mesh) -> Option<&'a [Nesting]> {
    let (lc, lf) = (coarse.nesting.len(), fine.nesting.len());
    if coarse.grid.is_some() || fine.grid.is_some() || lf < lc {
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
    (same_start && next_is_coarse && fine.n_cells() == coarse.n_cells() << (2 * (lf - lc)))
        .then(|| &fine.nesting[lc..])
}

/// A red refinement's nodal values: coarse nodes keep theirs, midpoints take the mean.
fn refined(nest: &Nesting, coarse_values: &[f64], comps: usize) -> Vec<f64> {
    let mut out = coarse_values[..nest.coarse_nodes * comps].to_vec();
    for &[a, b] in &nest.midpoints {
        for c in 0..comps {
            out.push(0.5 * (coarse_values[comps * a + c] + coarse_values[comps * b + c]));
        }
    }
    out
}

/// For every triangle of `fine`, the triangle of `coarse` containing it (nested meshes of
/// the same diagonal pattern, as for [`prolongate`]). On a fine triangle T, the interpolant
/// of a coarse P1 field is the coarse field itself, so ε(I v)|_T = ε(v)|_parent(T): strain
/// errors need no interpolation at all.
pub fn parent_triangles(coarse_mesh: &Mesh, fine_mesh: &Mesh) -> Option<Vec<u32>> {
    if let Some(levels) = refinements(coarse_mesh, fine_mesh) {
        let per = 4usize.pow(levels.len() as u32);
        return Some((0..fine_mesh.n_cells()).map(|t| (t / per) as u32).collect());
    }
    let (coarse, fine) = nested_grids(coarse_mesh, fine_mesh)?;
    let (rx, ry) = (fine.nx / coarse.nx, fine.ny / coarse.ny);
    // Centroids of a cell's two triangles, in thirds of the cell (see Mesh::rectangle).
    let centroids: [[usize; 2]; 2] = match fine.pattern {
        MeshPattern::Diagonal => [[2, 1], [1, 2]],
        _ => [[1, 1], [2, 2]],
    };
    let mut parents = Vec::with_capacity(fine_mesh.n_cells());
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
            let parents = parent_triangles(&coarse, &fine).unwrap();
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
            parent_triangles(&a, &Mesh::rectangle(1.0, 1.0, 4, 4, MeshPattern::Diagonal)).is_none()
        );
    }

    #[test]
    fn refuses_non_nested() {
        let a = Mesh::rectangle(1.0, 1.0, 3, 3, MeshPattern::Diagonal);
        let b = Mesh::rectangle(1.0, 1.0, 4, 4, MeshPattern::Diagonal);
        assert!(prolongate(&a, &vec![0.0; a.n_nodes()], 1, &b).is_none());
    }
}
