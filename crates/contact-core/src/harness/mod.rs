//! Harnesses that drive whole runs for their figures rather than their fields: the
//! hard-case table of the stability envelope ([`stress`]: `contact-sim stress`,
//! tests/stability.rs) and the speed figures ([`bench`]: `contact-sim bench`). Both drive
//! their runs through [`crate::run::Run`] like every other caller.

pub mod bench;
pub mod stress;
