//! Small dense helpers on nalgebra matrices (the Schur complement onto Γ3 is small and dense).

use nalgebra::{DMatrix, DVector};

/// Smallest eigenvalue of the symmetric matrix D A D with D = diag(d) (d > 0).
pub fn min_eig_scaled(a: &DMatrix<f64>, d: &[f64]) -> f64 {
    let n = a.nrows();
    if n == 0 {
        return f64::INFINITY;
    }
    let scaled = DMatrix::from_fn(n, n, |i, j| d[i] * a[(i, j)] * d[j]);
    scaled.symmetric_eigenvalues().min()
}

/// Largest eigenvalue of the symmetric tridiagonal matrix with diagonal `alphas` and
/// off-diagonal `betas` (the Lanczos matrix T_k; `betas` may hold one entry more than used).
pub fn tridiagonal_max_eig(alphas: &[f64], betas: &[f64]) -> f64 {
    let k = alphas.len();
    let t = DMatrix::from_fn(k, k, |i, j| {
        if i == j {
            alphas[i]
        } else if i + 1 == j || j + 1 == i {
            betas[i.min(j)]
        } else {
            0.0
        }
    });
    t.symmetric_eigenvalues().max()
}

/// Solves A_FF x = r for the principal sub-matrix of A on the index set `f`.
/// Returns None when the sub-matrix is not positive definite.
pub fn solve_principal(a: &DMatrix<f64>, f: &[usize], r: &[f64]) -> Option<Vec<f64>> {
    let m = f.len();
    let sub = DMatrix::from_fn(m, m, |i, j| a[(f[i], f[j])]);
    let chol = sub.cholesky()?;
    let x = chol.solve(&DVector::from_column_slice(r));
    Some(x.iter().copied().collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn principal_solve_and_min_eig() {
        let a = DMatrix::from_row_slice(3, 3, &[4.0, 1.0, 0.0, 1.0, 3.0, 0.0, 0.0, 0.0, 2.0]);
        let x = solve_principal(&a, &[0, 1], &[5.0, 4.0]).unwrap();
        assert!((x[0] - 1.0).abs() < 1e-14 && (x[1] - 1.0).abs() < 1e-14);
        // diag(1,1,0.5) A diag(1,1,0.5): the last eigenvalue 2·0.25 = 0.5 is the smallest.
        assert!((min_eig_scaled(&a, &[1.0, 1.0, 0.5]) - 0.5).abs() < 1e-12);
    }
}
