//! P1 finite elements on the triangulation: element kernels, the degree-of-freedom map with
//! Γ1/Γ3 constraints, pattern-once assembly of the scheme's matrices, load vectors and norms.

pub mod assembly;
pub mod cell_tensors;
pub mod dofs;
pub mod element;
pub mod incidence;
pub mod loads;
pub mod multilevel;
pub mod norms;
pub mod prolongation;
pub mod rigid_modes;

pub use cell_tensors::CellTensors;
pub use dofs::{DofMap, Slot};
pub use element::Geometry;
pub use incidence::NodeCells;
