//! A linear operator y = A x given by its action: an assembled [`Csr`], or an operator that is
//! a cheap modification of one (the truncated Newton Jacobian of the velocity step,
//! [`super::multigrid::truncated`]) and is never stored.

use super::Csr;

/// y ← A x for a square operator A of dimension [`LinearOperator::dim`].
pub trait LinearOperator {
    fn dim(&self) -> usize;
    fn apply(&self, x: &[f64], y: &mut [f64]);
}

impl LinearOperator for Csr {
    fn dim(&self) -> usize {
        self.nrows
    }

    fn apply(&self, x: &[f64], y: &mut [f64]) {
        self.mul_vec(x, y);
    }
}

impl<T: LinearOperator + ?Sized> LinearOperator for std::sync::Arc<T> {
    fn dim(&self) -> usize {
        (**self).dim()
    }

    fn apply(&self, x: &[f64], y: &mut [f64]) {
        (**self).apply(x, y);
    }
}

/// The leading n × n block A_II of a square [`Csr`] A, applied without copying it.
pub struct LeadingBlockOf<'a> {
    a: &'a Csr,
    n: usize,
}

impl<'a> LeadingBlockOf<'a> {
    pub fn new(a: &'a Csr, n: usize) -> Self {
        assert!(n <= a.nrows && n <= a.ncols);
        LeadingBlockOf { a, n }
    }
}

impl LinearOperator for LeadingBlockOf<'_> {
    fn dim(&self) -> usize {
        self.n
    }

    fn apply(&self, x: &[f64], y: &mut [f64]) {
        let a = self.a;
        for (r, yr) in y[..self.n].iter_mut().enumerate() {
            let row = a.indptr[r]..a.indptr[r + 1];
            // Columns are sorted: the leading ones come first.
            let cols = &a.indices[row.clone()];
            let end = cols.partition_point(|&c| (c as usize) < self.n);
            *yr = cols[..end]
                .iter()
                .zip(&a.values[row][..end])
                .map(|(&c, &v)| v * x[c as usize])
                .sum();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn leading_block_product_equals_the_copied_block() {
        let n = 9;
        let t = (0..n)
            .flat_map(|i| (0..n).map(move |j| (i, j)))
            .filter(|(i, j)| (i + 2 * j) % 3 != 1 || i == j)
            .map(|(i, j)| (i, j, 1.0 + (i * n + j) as f64 * 0.37))
            .collect();
        let a = Csr::from_triplets(n, n, t);
        let x: Vec<f64> = (0..6).map(|i| (i as f64).cos()).collect();
        let (mut y, mut want) = (vec![0.0; 6], vec![0.0; 6]);
        LeadingBlockOf::new(&a, 6).apply(&x, &mut y);
        a.block(0..6, 0..6).mul_vec(&x, &mut want);
        assert_eq!(y, want);
    }
}
