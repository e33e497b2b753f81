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
