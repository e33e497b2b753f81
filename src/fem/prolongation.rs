//! Interpolation of a P1 field from a coarse structured mesh onto a finer nested one
//! (SCHEME.md: meshes of h and h/2 are nested, so this is exact for P1 fields). Used by
//! convergence studies to compare a coarse solution with the reference on the fine mesh.

use crate::mesh::Mesh;
use crate::problem::MeshPattern;

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
    if coarse.pattern != fine.pattern || coarse.pattern == MeshPattern::Cross {
        return None;
    }
    if fine.nx % coarse.nx != 0 || fine.ny % coarse.ny != 0 {
        return None;
    }
    let (rx, ry) = (fine.nx / coarse.nx, fine.ny / coarse.ny);
    let cgrid = |i: usize, j: usize| j * (coarse.nx + 1) + i;
    let mut out = Vec::with_capacity(fine.n_nodes() * comps);
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
                (0..m.triangles.len())
                    .map(|t| m.area(t) * m.triangles[t].iter().map(|&i| v[i]).sum::<f64>() / 3.0)
                    .sum()
            };
            assert!((integral(&coarse, &cz) - integral(&fine, &fz)).abs() < 1e-12);
        }
    }

    #[test]
    fn refuses_non_nested() {
        let a = Mesh::rectangle(1.0, 1.0, 3, 3, MeshPattern::Diagonal);
        let b = Mesh::rectangle(1.0, 1.0, 4, 4, MeshPattern::Diagonal);
        assert!(prolongate(&a, &vec![0.0; a.n_nodes()], 1, &b).is_none());
    }
}
