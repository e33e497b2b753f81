//! The damage source φ(ε, ζ) of (4.2) with its constants as parameters.

use super::Tensor;
#[cfg(test)]
use super::Tensor2;
use crate::problem::DamageSource;

/// φ(τ, ζ) = a (1 − ζ)/ζ − b |τ|² for ζ ≥ ζ*, and a (1 − ζ*)/ζ* − b |τ|² for ζ < ζ*
/// (|τ| the Frobenius norm). Continuous at ζ = ζ*; the paper has a = 2, b = 20, ζ* = 0.2.
#[inline]
pub fn phi<const D: usize>(src: &DamageSource, eps: &Tensor<D>, zeta: f64) -> f64 {
    let z = zeta.max(src.zeta_star);
    src.a * (1.0 - z) / z - src.b * eps.norm_squared()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_branches() {
        let s = DamageSource {
            a: 2.0,
            b: 20.0,
            zeta_star: 0.2,
        };
        let e = Tensor2::new(0.1, 0.0, 0.0, 0.0);
        assert!((phi(&s, &e, 1.0) + 0.2).abs() < 1e-15);
        assert!((phi(&s, &e, 0.5) - (2.0 - 0.2)).abs() < 1e-15);
        // Below ζ* the value is frozen at 8 − 20|τ|².
        assert!((phi(&s, &e, 0.05) - 7.8).abs() < 1e-14);
        assert!((phi(&s, &e, 0.2) - 7.8).abs() < 1e-14);
    }
}
