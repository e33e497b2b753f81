//! Harnesses that drive whole runs for their figures rather than their fields: the
//! hard-case table of the stability envelope ([`stress`]: `contact-sim stress`,
//! tests/stability.rs), the speed figures ([`bench`]: `contact-sim bench`) and adaptive
//! against uniform refinement at equal error ([`adaptivity`]: `contact-sim bench --adapt`).
//! They drive their runs through [`crate::run::Run`] like every other caller.

pub mod adaptivity;
pub mod bench;
pub mod stress;
