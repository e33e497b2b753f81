//! What a run produces: the summary JSON (norms per step, solver iterations and residuals,
//! timings, smallness estimate) and the per-step fields.

pub mod fields;
pub mod stored;
pub mod summary;
pub mod surface;
pub mod vtk;

pub use summary::Summary;
