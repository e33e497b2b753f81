//! Sparse storage and the cached sparse Cholesky factorisation (faer), plus small dense helpers.

pub mod cholesky;
pub mod csr;
pub mod dense;
pub mod schur;

pub use cholesky::Cholesky;
pub use csr::Csr;
pub use schur::{schur_complement, SchurPath};
