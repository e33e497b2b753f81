//! contact-sim: quasistatic frictional contact of a viscoelastic body with damage.
//!
//! The numerics is the fully discrete scheme (Problem 3.1) of W. Han, M. Jureczka, A. Ochal,
//! "Numerical analysis of a contact problem with damage", J. Comput. Appl. Math. 377 (2020)
//! 112886, with the discrete choices fixed in SCHEME.md. Data flows one way:
//! scene JSON → [`scene::validate`] → [`problem::Problem`] → [`mesh`] and [`fem`] matrices →
//! [`solve::stepper`] time steps → [`output`] summary and fields.
//!
//! Nothing in this library knows about HTTP.
#![forbid(unsafe_code)]

pub mod bench;
pub mod fem;
pub mod laws;
pub mod linalg;
pub mod mesh;
pub mod output;
pub mod problem;
pub mod run;
pub mod scene;
pub mod service;
pub mod solve;
pub mod stress;
pub mod study;
#[cfg(test)]
mod test_rng;
