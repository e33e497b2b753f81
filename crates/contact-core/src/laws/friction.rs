//! The friction potential on Γ3: j(ξ) = ∫_0^|ξ| μ(r) dr with the bound μ(r) ≥ 0, so that
//! ∂j(ξ) = μ(|ξ|) ξ/|ξ| for ξ ≠ 0 and the Clarke subdifferential at 0 is the ball of radius
//! μ(0). A decreasing μ makes j non-convex (a true hemivariational inequality); its
//! relaxed-monotonicity constant c2τ of (2.31) is the steepest descent of μ.

use crate::problem::FrictionLaw;

impl FrictionLaw {
    /// Friction bound μ(r), r = |ξ| ≥ 0.
    pub fn mu(&self, r: f64) -> f64 {
        match self {
            FrictionLaw::Tresca { g } => *g,
            FrictionLaw::SlipWeakening { mu0, mu1, alpha } => {
                mu1 + (mu0 - mu1) * (-alpha * r).exp()
            }
            FrictionLaw::PiecewiseLinear { points } => {
                let (i, t) = locate(points, r);
                match i {
                    None => points[points.len() - 1][1],
                    Some(i) => points[i][1] + t * (points[i + 1][1] - points[i][1]),
                }
            }
        }
    }

    /// dμ/dr at r (right derivative at the kinks of a table).
    pub fn dmu(&self, r: f64) -> f64 {
        match self {
            FrictionLaw::Tresca { .. } => 0.0,
            FrictionLaw::SlipWeakening { mu0, mu1, alpha } => {
                -alpha * (mu0 - mu1) * (-alpha * r).exp()
            }
            FrictionLaw::PiecewiseLinear { points } => match locate(points, r).0 {
                None => 0.0,
                Some(i) => (points[i + 1][1] - points[i][1]) / (points[i + 1][0] - points[i][0]),
            },
        }
    }

    /// The potential j(r) = ∫_0^r μ(s) ds.
    pub fn potential(&self, r: f64) -> f64 {
        match self {
            FrictionLaw::Tresca { g } => g * r,
            FrictionLaw::SlipWeakening { mu0, mu1, alpha } => {
                if *alpha == 0.0 {
                    mu0 * r
                } else {
                    mu1 * r + (mu0 - mu1) * (1.0 - (-alpha * r).exp()) / alpha
                }
            }
            FrictionLaw::PiecewiseLinear { points } => {
                let mut acc = 0.0;
                for w in points.windows(2) {
                    let (r0, r1) = (w[0][0], w[1][0]);
                    if r <= r0 {
                        return acc;
                    }
                    let top = r.min(r1);
                    let mu_top = w[0][1] + (top - r0) * (w[1][1] - w[0][1]) / (r1 - r0);
                    acc += 0.5 * (w[0][1] + mu_top) * (top - r0);
                    if r <= r1 {
                        return acc;
                    }
                }
                acc + points[points.len() - 1][1] * (r - points[points.len() - 1][0])
            }
        }
    }

    /// j(|x + δ|) − j(|x|) for a node's tangential velocity x moved by δ (2D: second entries
    /// zero), with |x + δ| − |x| = δ·(2x + δ) / (|x + δ| + |x|), formed without cancellation.
    pub fn node_potential_change(&self, x: [f64; 2], delta: [f64; 2]) -> f64 {
        let y = [x[0] + delta[0], x[1] + delta[1]];
        let (r0, r1) = (x[0].hypot(x[1]), y[0].hypot(y[1]));
        let dr = if r0 + r1 > 0.0 {
            (delta[0] * (x[0] + y[0]) + delta[1] * (x[1] + y[1])) / (r0 + r1)
        } else {
            0.0
        };
        self.potential_change(r0, r1, dr)
    }

    /// j(r1) − j(r0) = ∫_{r0}^{r1} μ, given dr = r1 − r0 computed without cancellation. Near the
    /// solution the steps' energy changes are far below the rounding of j itself, so the
    /// difference is integrated, not subtracted.
    pub fn potential_change(&self, r0: f64, r1: f64, dr: f64) -> f64 {
        match self {
            FrictionLaw::Tresca { g } => g * dr,
            FrictionLaw::SlipWeakening { mu0, mu1, alpha } => {
                if *alpha == 0.0 {
                    mu0 * dr
                } else {
                    // ∫ e^(−α s) = e^(−α r0) (1 − e^(−α dr)) / α.
                    mu1 * dr + (mu0 - mu1) * (-alpha * r0).exp() * -(-alpha * dr).exp_m1() / alpha
                }
            }
            FrictionLaw::PiecewiseLinear { points } => {
                // μ is linear between consecutive breakpoints (and constant outside them): the
                // trapezoid rule on each piece is exact.
                let (lo, hi, sign) = if r1 >= r0 {
                    (r0, r1, 1.0)
                } else {
                    (r1, r0, -1.0)
                };
                let inside = points.iter().map(|p| p[0]).filter(|&t| t > lo && t < hi);
                let mut total = 0.0;
                let mut a = lo;
                let mut pieces = 0;
                for t in inside.chain(std::iter::once(hi)) {
                    total += (t - a) * 0.5 * (self.mu(a) + self.mu(t));
                    a = t;
                    pieces += 1;
                }
                if pieces == 1 {
                    // One piece: its length is dr itself, not the rounded hi − lo.
                    dr * 0.5 * (self.mu(r0) + self.mu(r1))
                } else {
                    sign * total
                }
            }
        }
    }

    /// c2τ of (2.31): the relaxed-monotonicity constant of ∂j, i.e. max(0, −min_r μ'(r)).
    /// 0 for convex laws.
    pub fn relaxed_monotonicity(&self) -> f64 {
        match self {
            FrictionLaw::Tresca { .. } => 0.0,
            FrictionLaw::SlipWeakening { mu0, mu1, alpha } => (alpha * (mu0 - mu1)).max(0.0),
            FrictionLaw::PiecewiseLinear { points } => points
                .windows(2)
                .map(|w| -(w[1][1] - w[0][1]) / (w[1][0] - w[0][0]))
                .fold(0.0, f64::max),
        }
    }
}

/// Table interval containing r: (Some(i), t) with r in [r_i, r_{i+1}), t the local coordinate;
/// (None, _) beyond the last point.
fn locate(points: &[[f64; 2]], r: f64) -> (Option<usize>, f64) {
    let i = points.partition_point(|p| p[0] <= r);
    if i == 0 {
        return (Some(0).filter(|_| points.len() > 1), 0.0);
    }
    if i >= points.len() {
        return (None, 0.0);
    }
    let (a, b) = (points[i - 1][0], points[i][0]);
    (Some(i - 1), (r - a) / (b - a))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn laws() -> Vec<FrictionLaw> {
        vec![
            FrictionLaw::Tresca { g: 20.0 },
            FrictionLaw::SlipWeakening {
                mu0: 1.2,
                mu1: 0.4,
                alpha: 3.0,
            },
            FrictionLaw::PiecewiseLinear {
                points: vec![[0.0, 1.0], [0.5, 0.6], [1.0, 0.7]],
            },
        ]
    }

    #[test]
    fn potential_is_antiderivative_of_mu() {
        for law in laws() {
            for &r in &[0.0, 0.1, 0.49, 0.5, 0.77, 1.0, 2.5] {
                let h = 1e-6;
                let fd = (law.potential(r + h) - law.potential((r - h).max(0.0)))
                    / (r + h - (r - h).max(0.0));
                let expect = 0.5 * (law.mu(r + h) + law.mu((r - h).max(0.0)));
                assert!(
                    (fd - expect).abs() < 1e-6,
                    "{law:?} r={r}: {fd} vs {expect}"
                );
            }
        }
    }

    #[test]
    fn slopes_and_relaxed_monotonicity() {
        let l = laws();
        assert_eq!(l[0].relaxed_monotonicity(), 0.0);
        assert!((l[1].relaxed_monotonicity() - 2.4).abs() < 1e-15);
        assert!((l[2].relaxed_monotonicity() - 0.8).abs() < 1e-15);
        assert!((l[1].dmu(0.0) + 2.4).abs() < 1e-15);
        assert!((l[2].dmu(0.25) + 0.8).abs() < 1e-15 && (l[2].dmu(0.75) - 0.2).abs() < 1e-15);
        assert_eq!(l[2].mu(3.0), 0.7);
        assert_eq!(l[2].dmu(3.0), 0.0);
    }
}
