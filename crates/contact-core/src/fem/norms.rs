//! The norms (docs/src/explanation/numerics.md#norms): |v|_V = ‖ε(v)‖_L2(Ω) and |ζ|_Z0 = (ζᵀ M ζ)^½.

use super::Geometry;
use crate::linalg::Csr;
use crate::mesh::Mesh;

/// ‖ε(v)‖_L2 = (Σ_T |T| ε:ε)^½ for a global nodal vector field v.
pub fn strain_norm<const D: usize>(mesh: &Mesh<D>, geo: &Geometry<D>, v: &[f64]) -> f64 {
    (0..mesh.n_cells())
        .map(|t| geo.measure(t) * geo.strain(mesh, t, v).norm_squared())
        .sum::<f64>()
        .sqrt()
}

/// (zᵀ M z)^½ with the consistent mass matrix M.
/// NaN when z is not finite.
pub fn mass_norm(m: &Csr, z: &[f64], scratch: &mut [f64]) -> f64 {
    m.mul_vec(z, scratch);
    let squared: f64 = z.iter().zip(scratch.iter()).map(|(a, b)| a * b).sum();
    // Rounding can make zᵀMz slightly negative; `f64::max(0.0)` would also turn NaN into 0
    // and hide a broken ζ from the finiteness checks.
    if squared < 0.0 {
        0.0
    } else {
        squared.sqrt()
    }
}
