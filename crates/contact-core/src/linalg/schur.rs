//! The Schur complement of a bordered SPD matrix
//!   K = [K_II K_IC; K_CI K_CC]   (I: the first `lead` unknowns, C: the last m)
//! onto its trailing unknowns: S = K_CC − K_CI K_II⁻¹ K_IC (m × m, dense). Two ways
//! ([`SchurPath`]):
//! - **trailing block** (the default): K is factored whole, ordered as K_II's own factor
//!   (AMD) first and C last, P K Pᵀ = L Lᵀ with L = [L_II 0; L_CI L_CC]; then
//!   S = L_CC L_CCᵀ is read off the factor with no solve at all. The factor is dropped
//!   afterwards: with C last it has more fill (L_CI), so solves keep using K_II's own factor;
//! - **blocked solves**: S column by column from m solves with K_II's factor,
//!   [`SCHUR_BLOCK`] right-hand sides at a time (BLAS-3 supernodal kernels).
//!
//! The trailing block costs one more factorisation (its dense L_CC adds m³/3 flops), the
//! blocked solves about 4 m · nnz(L) flops: at the 1/16 box (m = 1,088,
//! nnz(L) = 1.8·10⁷) that is 4·10⁸ against 8·10¹⁰ (`contact-sim bench --schur`).

use super::cholesky::Cholesky;
use super::solver::{LinearSolver, NotConverged};
use super::Csr;
use nalgebra::DMatrix;

/// Schur complements by blocked solves take this many right-hand sides at a time, bounding
/// the dense scratch to n_I × 32 values while keeping the supernodal solves BLAS-3.
pub const SCHUR_BLOCK: usize = 32;

/// How S is obtained (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SchurPath {
    #[default]
    TrailingBlock,
    BlockedSolves,
}

/// S of `k` (n × n, full storage) onto its last n − `lead` unknowns, `k_ii` the factor of
/// its leading block; exactly symmetric. Returns the path actually taken: the trailing block
/// falls back to blocked solves should the analysis not keep C last or K not factor.
pub fn schur_complement(
    k: &Csr,
    lead: usize,
    k_ii: &Cholesky,
    path: SchurPath,
) -> (DMatrix<f64>, SchurPath) {
    let trailing = match path {
        SchurPath::TrailingBlock => trailing_block(k, lead, &k_ii.forward()),
        SchurPath::BlockedSolves => None,
    };
    let (s, path) = match trailing {
        Some(l_cc) => (&l_cc * l_cc.transpose(), SchurPath::TrailingBlock),
        None => (blocked_solves(k, lead, k_ii), SchurPath::BlockedSolves),
    };
    // Symmetrise against rounding so the dense Cholesky sees an exactly symmetric matrix.
    let st = s.transpose();
    ((s + st) * 0.5, path)
}

/// Relative max-norm residual of each solve of [`schur_by_solves`].
pub const SCHUR_COLUMN_TOLERANCE: f64 = 1e-13;

/// S of `k` onto its last n − `lead` unknowns with any solver of K_II (the multigrid path):
/// column c is K_CC e_c − K_CI K_II⁻¹ K_IC e_c, each solve to [`SCHUR_COLUMN_TOLERANCE`]
/// relative to its right-hand side; symmetrised. An m × m dense result: only where it fits.
pub fn schur_by_solves(
    k: &Csr,
    lead: usize,
    k_ii: &mut LinearSolver,
) -> Result<DMatrix<f64>, NotConverged> {
    let (n, m) = (k.nrows, k.nrows - lead);
    let k_ci = k.block(lead..n, 0..lead);
    let mut s = DMatrix::zeros(m, m);
    let (mut rhs, mut sol, mut col) = (vec![0.0; lead], vec![0.0; lead], vec![0.0; m]);
    for c in 0..m {
        rhs.iter_mut().for_each(|v| *v = 0.0);
        // Column c of K_IC is row c of K_CI (K is symmetric).
        for p in k_ci.indptr[c]..k_ci.indptr[c + 1] {
            rhs[k_ci.indices[p] as usize] = k_ci.values[p];
        }
        let scale = rhs.iter().fold(f64::MIN_POSITIVE, |a, v| a.max(v.abs()));
        sol.iter_mut().for_each(|v| *v = 0.0);
        k_ii.solve(&rhs, &mut sol, SCHUR_COLUMN_TOLERANCE * scale)
            .map_err(|e| NotConverged {
                iterations: e.iterations,
                residual: e.residual / scale,
            })?;
        k_ci.mul_vec(&sol, &mut col);
        for r in 0..m {
            s[(r, c)] = k.get(lead + r, lead + c) - col[r];
        }
    }
    let st = s.transpose();
    Ok((s + st) * 0.5)
}

/// L_CC of K ordered `interior_order` (of K_II) then C: the rows and columns ≥ lead of the
/// factor, lower triangular. None if the analysis moved C (it postorders the elimination
/// tree; C, eliminated last, is the root's chain and stays last) or K does not factor.
fn trailing_block(k: &Csr, lead: usize, interior_order: &[usize]) -> Option<DMatrix<f64>> {
    let n = k.nrows;
    let m = n - lead;
    let order: Vec<usize> = interior_order.iter().copied().chain(lead..n).collect();
    let factor = Cholesky::with_ordering(k.lower_csc().as_ref(), Some(&order)).ok()?;
    if factor.forward()[lead..]
        .iter()
        .enumerate()
        .any(|(i, &p)| p != lead + i)
    {
        return None;
    }
    let mut l = DMatrix::zeros(m, m);
    let factor = factor.supernodal();
    for s in 0..factor.symbolic().n_supernodes() {
        let node = factor.supernode(s);
        let (start, pattern, val) = (node.start(), node.pattern(), node.val());
        let width = val.ncols();
        for c in 0..width {
            let j = start + c;
            if j < lead {
                continue;
            }
            for r in c..width {
                l[(start + r - lead, j - lead)] = val[(r, c)];
            }
            for (q, &i) in pattern.iter().enumerate() {
                l[(i - lead, j - lead)] = val[(width + q, c)];
            }
        }
    }
    Some(l)
}

fn blocked_solves(k: &Csr, lead: usize, k_ii: &Cholesky) -> DMatrix<f64> {
    let (n_i, m) = (lead, k.nrows - lead);
    let k_ci = k.block(lead..k.nrows, 0..lead);
    let mut s = DMatrix::zeros(m, m);
    for i in 0..m {
        for j in 0..m {
            s[(i, j)] = k.get(n_i + i, n_i + j);
        }
    }
    let mut start = 0;
    while start < m {
        let cols = SCHUR_BLOCK.min(m - start);
        // Z = K_II⁻¹ K_IC[:, start..start+cols]; column c of K_IC is row c of K_CI.
        let mut z = vec![0.0; n_i * cols];
        for c in 0..cols {
            let row = start + c;
            for p in k_ci.indptr[row]..k_ci.indptr[row + 1] {
                z[c * n_i + k_ci.indices[p] as usize] = k_ci.values[p];
            }
        }
        k_ii.solve_block_in_place(&mut z, cols);
        let mut col = vec![0.0; m];
        for c in 0..cols {
            k_ci.mul_vec(&z[c * n_i..(c + 1) * n_i], &mut col);
            for i in 0..m {
                s[(i, start + c)] -= col[i];
            }
        }
        start += cols;
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The 2D Laplacian on an nx × ny grid (5-point, Dirichlet, a varying diagonal): a
    /// connected SPD matrix.
    fn laplace_2d(nx: usize, ny: usize) -> Csr {
        let n = nx * ny;
        let mut t = Vec::new();
        for j in 0..ny {
            for i in 0..nx {
                let p = j * nx + i;
                t.push((p, p, 4.0 + 0.01 * p as f64));
                if i + 1 < nx {
                    t.push((p, p + 1, -1.0));
                    t.push((p + 1, p, -1.0));
                }
                if j + 1 < ny {
                    t.push((p, p + nx, -1.0));
                    t.push((p + nx, p, -1.0));
                }
            }
        }
        Csr::from_triplets(n, n, t)
    }

    #[test]
    fn both_paths_give_the_inverse_of_the_trailing_block_of_the_inverse() {
        let k = laplace_2d(12, 9);
        let (n, m) = (k.nrows, 12);
        let lead = n - m;
        let k_ii = Cholesky::new(k.block(0..lead, 0..lead).lower_csc().as_ref()).unwrap();
        let (s1, p1) = schur_complement(&k, lead, &k_ii, SchurPath::TrailingBlock);
        let (s2, p2) = schur_complement(&k, lead, &k_ii, SchurPath::BlockedSolves);
        assert_eq!(
            (p1, p2),
            (SchurPath::TrailingBlock, SchurPath::BlockedSolves)
        );
        assert!(
            (&s1 - &s2).amax() < 1e-12 * s2.amax(),
            "{}",
            (&s1 - &s2).amax()
        );
        // Column by column with any solver of K_II (the multigrid path's way): a direct one
        // and multigrid-preconditioned CG give the same S.
        let block = k.block(0..lead, 0..lead);
        let mut direct = LinearSolver::direct(&block).unwrap();
        let s3 = schur_by_solves(&k, lead, &mut direct).unwrap();
        assert!((&s3 - &s2).amax() < 1e-12 * s2.amax());
        let mut mg = LinearSolver::multigrid(
            std::sync::Arc::new(block),
            crate::linalg::multigrid::Blocks::scalar(lead),
            crate::linalg::multigrid::Coarsening::Aggregation {
                nullspace: vec![1.0; lead],
                k: 1,
            },
        )
        .unwrap();
        let s4 = schur_by_solves(&k, lead, &mut mg).unwrap();
        assert!(
            (&s4 - &s2).amax() < 1e-10 * s2.amax(),
            "{}",
            (&s4 - &s2).amax()
        );
        assert_eq!(s1, s1.transpose());
        // S⁻¹ is the C block of K⁻¹.
        let dense = DMatrix::from_fn(n, n, |i, j| k.get(i, j));
        let inv = dense.try_inverse().unwrap();
        let c_block = inv.view((lead, lead), (m, m)).into_owned();
        assert!((&s1 * c_block - DMatrix::identity(m, m)).amax() < 1e-10);
    }

    #[test]
    fn without_trailing_unknowns_s_is_empty() {
        let k = laplace_2d(5, 4);
        let k_ii = Cholesky::new(k.lower_csc().as_ref()).unwrap();
        let (s, _) = schur_complement(&k, k.nrows, &k_ii, SchurPath::TrailingBlock);
        assert_eq!(s.nrows(), 0);
    }
}
