//! The physics as pointwise functions: viscosity A and elasticity B of the constitutive law
//! (2.1), the damage source φ of (2.2)/(4.2), and the friction bound μ(r) of j on Γ3.
//! Tensors are symmetric d × d matrices (nalgebra `SMatrix`, d = 2 or 3).

pub mod constitutive;
pub mod damage_source;
pub mod friction;

pub use nalgebra::Matrix2 as Tensor2;

/// A d × d tensor.
pub type Tensor<const D: usize> = nalgebra::SMatrix<f64, D, D>;
