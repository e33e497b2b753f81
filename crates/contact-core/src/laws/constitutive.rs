//! σ = A ε(w) + B(ε(u), ζ), equation (2.1), with A and B of (4.1) or the von Mises B of
//! (2.15–2.16).

use super::Tensor;
#[cfg(test)]
use super::Tensor2;
use crate::problem::{Elasticity, Viscosity};

/// A(τ) = 2η τ + ξ tr(τ) I, (4.1).
#[inline]
pub fn viscous_stress<const D: usize>(a: &Viscosity, eps: &Tensor<D>) -> Tensor<D> {
    eps * (2.0 * a.eta) + Tensor::<D>::identity() * (a.xi * eps.trace())
}

/// Deviatoric part τ^D = τ − tr(τ)/d I.
#[inline]
pub fn deviator<const D: usize>(t: &Tensor<D>) -> Tensor<D> {
    t - Tensor::<D>::identity() * (t.trace() / D as f64)
}

/// B(ε, ζ): (4.1) ζ(2μ ε + λ tr(ε) I), or (2.15–2.16) η_B (ε − P_K(ζ) ε) where P_K(ζ) is the
/// projection onto K(ζ) = {τ : |τ^D| ≤ ζ σ_Y}: it keeps the spherical part and shrinks the
/// deviator to radius ζ σ_Y, so ε − P ε = ε^D · max(0, 1 − ζσ_Y/|ε^D|).
#[inline]
pub fn elastic_stress<const D: usize>(b: &Elasticity, eps: &Tensor<D>, zeta: f64) -> Tensor<D> {
    match *b {
        Elasticity::Linear { mu, lambda } => {
            (eps * (2.0 * mu) + Tensor::<D>::identity() * (lambda * eps.trace())) * zeta
        }
        Elasticity::VonMises { eta_b, sigma_y } => {
            let dev = deviator(eps);
            let n = dev.norm();
            let radius = zeta * sigma_y;
            if n <= radius {
                Tensor::<D>::zeros()
            } else {
                dev * (eta_b * (1.0 - radius / n))
            }
        }
    }
}

/// Von Mises equivalent stress sqrt(3/2 · σ^D : σ^D) with the d-dimensional deviator.
#[inline]
pub fn von_mises<const D: usize>(s: &Tensor<D>) -> f64 {
    (1.5 * deviator(s).norm_squared()).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn linear_laws_match_lame_form() {
        let e = Tensor2::new(0.1, 0.02, 0.02, -0.05);
        let s = viscous_stress(&Viscosity { eta: 2.0, xi: 3.0 }, &e);
        assert!((s[(0, 0)] - (4.0 * 0.1 + 3.0 * 0.05)).abs() < 1e-15);
        assert!((s[(0, 1)] - 4.0 * 0.02).abs() < 1e-15);
        let b = elastic_stress(
            &Elasticity::Linear {
                mu: 4.0,
                lambda: 4.0,
            },
            &e,
            0.5,
        );
        assert!((b[(1, 1)] - 0.5 * (8.0 * -0.05 + 4.0 * 0.05)).abs() < 1e-15);
    }

    #[test]
    fn von_mises_elasticity_is_projection_residual() {
        let b = Elasticity::VonMises {
            eta_b: 2.0,
            sigma_y: 1.0,
        };
        // Purely spherical strain lies in K(ζ): no stress.
        assert_eq!(
            elastic_stress(&b, &(Tensor2::identity() * 5.0), 1.0),
            Tensor2::zeros()
        );
        // ε^D = [[1, 1], [1, -1]] has norm 2; with ζσ_Y = 0.5: B = η_B (1 − 0.5/2) ε^D.
        let e = Tensor2::new(1.3, 1.0, 1.0, -0.7);
        let s = elastic_stress(&b, &e, 0.5);
        let expect = Tensor2::new(1.0, 1.0, 1.0, -1.0) * (2.0 * 0.75);
        assert!((s - expect).norm() < 1e-13);
    }
}
