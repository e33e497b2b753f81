//! The linear algebra of the scheme: sparse storage, the linear-solver layer
//! ([`solver::LinearSolver`]: the direct factor, or conjugate gradients preconditioned by a
//! multigrid V-cycle), and small dense helpers. One algorithm per file: the cached sparse
//! Cholesky ([`cholesky`]), conjugate gradients ([`pcg`]) and their starting guesses from
//! earlier solutions ([`projection`]), the multigrid hierarchy with its
//! coarsening and smoother ([`multigrid`]), sparse products ([`galerkin`]), the Schur
//! complement onto Γ3 ([`schur`]), the nested-dissection ordering ([`nested_dissection`]),
//! and the threads every kernel splits its work over ([`par`]).

pub mod block_csr;
pub mod block_products;
pub mod cholesky;
pub mod csr;
pub mod dense;
pub mod galerkin;
pub mod multigrid;
pub mod nested_dissection;
pub mod operator;
pub mod par;
pub mod pcg;
pub mod projection;
pub mod schur;
pub mod solver;
pub mod sparse;

pub use crate::problem::LinearPath;
pub use cholesky::{Cholesky, CholeskyPlan};
pub use csr::Csr;
pub use operator::LinearOperator;
pub use schur::{schur_complement, SchurPath};
pub use solver::LinearSolver;
pub use sparse::Sparse;
