//! contact-core: the numerical core of contact-sim — quasistatic frictional contact of a
//! viscoelastic body with damage.
//!
//! The numerics is the fully discrete scheme (Problem 3.1) of W. Han, M. Jureczka, A. Ochal,
//! "Numerical analysis of a contact problem with damage", J. Comput. Appl. Math. 377 (2020)
//! 112886, with the discrete choices written down in `docs/src/explanation/numerics.md`. Data flows one way:
//! scene JSON → [`scene::validate`] → [`problem::Problem`] → [`mesh`] and [`fem`] matrices →
//! [`solve::stepper`] time steps → [`output`] summary and fields. [`run`] drives every run
//! (the only time loop, with hooks), [`admission`] checks a run against a host's per-job
//! limits before any numeric work, [`estimate`] gives a run its error bar, [`study`] runs
//! convergence and target studies, [`harness`] the stress table and the bench.
//!
//! This crate knows nothing about HTTP, storage or command lines (a CI step checks its
//! dependency tree).
#![forbid(unsafe_code)]

pub mod a_posteriori;
pub mod admission;
pub mod estimate;
pub mod expr;
pub mod fem;
pub mod harness;
pub mod laws;
pub mod linalg;
pub mod memory;
pub mod mesh;
pub mod msh;
pub mod output;
pub mod problem;
pub mod run;
pub mod scene;
pub mod solve;
pub mod study;
