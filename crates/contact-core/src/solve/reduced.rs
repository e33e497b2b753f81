//! The data of the velocity step's reduced problem on Γ3 (docs/src/explanation/numerics.md, "The reduced
//! non-smooth problem"):
//!
//!   minimise Φ(x) = ½ xᵀ S x − bᵀ x + Σ_i ω_i j(|x_i|),   j(r) = ∫_0^r μ(s) ds,
//!
//! where x_i is the tangential velocity of Γ3 node i, with d − 1 components (one in 2D, two in
//! 3D), and |·| is the Euclidean norm. Its solvers are [`super::friction_reduced`] (d = 2)
//! and [`super::friction_isotropic`] (d = 3).

use super::friction_node;
use crate::problem::FrictionLaw;
use faer::{Accum, MatMut, MatRef, Par};
use nalgebra::DMatrix;

/// The reduced problem's data.
pub struct Reduced<'a> {
    /// The Schur complement, (d − 1) m × (d − 1) m; DOFs (d − 1) i .. (d − 1)(i + 1) are node
    /// i's components.
    pub s: &'a DMatrix<f64>,
    /// The reduced load, ordered as S.
    pub b: &'a [f64],
    /// ω_i, one per node (length m).
    pub weights: &'a [f64],
    pub law: &'a FrictionLaw,
    /// Force scale of the relative residual; None: ‖b‖_∞. The velocity step passes the
    /// scale of its full load so both residuals are relative to the same quantity.
    pub scale: Option<f64>,
}

impl Reduced<'_> {
    /// Number of Γ3 nodes m.
    pub fn nodes(&self) -> usize {
        self.weights.len()
    }

    /// Components per node: d − 1.
    pub fn block(&self) -> usize {
        self.b.len() / self.nodes().max(1)
    }

    /// g = S x − b.
    pub fn gradient(&self, x: &[f64]) -> Vec<f64> {
        let mut g = vec![0.0; x.len()];
        mul(self.s, x, &mut g);
        g.iter_mut().zip(self.b).for_each(|(g, b)| *g -= b);
        g
    }

    /// Φ(x).
    pub fn energy(&self, x: &[f64]) -> f64 {
        let g = self.gradient(x);
        let quadratic: f64 = x
            .iter()
            .zip(&g)
            .zip(self.b)
            .map(|((x, g), b)| 0.5 * x * (g - b))
            .sum();
        quadratic + self.friction_energy(x)
    }

    /// Σ_i ω_i j(|x_i|).
    pub fn friction_energy(&self, x: &[f64]) -> f64 {
        x.chunks(self.block().max(1))
            .zip(self.weights)
            .map(|(xi, w)| {
                w * self
                    .law
                    .potential(xi.iter().map(|v| v * v).sum::<f64>().sqrt())
            })
            .sum()
    }

    /// Scale of the problem's forces, for relative residuals.
    pub fn scale(&self) -> f64 {
        let b = self.b.iter().fold(0.0f64, |s, v| s.max(v.abs()));
        self.scale.unwrap_or(b).max(f64::MIN_POSITIVE)
    }

    /// Relative KKT residual: the largest violation of the per-node stick/slip conditions,
    /// divided by the scale (given, or ‖b‖_∞).
    pub fn residual(&self, x: &[f64]) -> f64 {
        let g = self.gradient(x);
        friction_node::kkt_violation(self.block(), &g, x, self.weights, self.law) / self.scale()
    }
}

/// out = S v, with faer's kernel on S's own storage (S is never copied).
pub fn mul(s: &DMatrix<f64>, v: &[f64], out: &mut [f64]) {
    let n = v.len();
    faer::linalg::matmul::matmul(
        MatMut::from_column_major_slice_mut(out, n, 1),
        Accum::Replace,
        MatRef::from_column_major_slice(s.as_slice(), n, n),
        MatRef::from_column_major_slice(v, n, 1),
        1.0,
        Par::Seq,
    );
}
