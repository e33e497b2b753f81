//! The friction law at one Γ3 node, pointwise: the tangential velocity x_i has d − 1
//! components (one in 2D, the `line`; two in 3D, the `plane`), g_i is the node's force
//! residual (the gradient of the smooth part of the energy), and the optimality (Clarke
//! stationarity) conditions of (3.13) at the node are
//!   stick:  x_i = 0  and |g_i| ≤ ω_i μ(0),
//!   slip:   x_i ≠ 0  and g_i + ω_i μ(|x_i|) x_i/|x_i| = 0,
//! with the Euclidean norm |·|. This module is their only statement: the violation of these
//! conditions ([`kkt_violation`]), the exact stick test of a load ([`all_stick`]) and the
//! proximal map of c·j(|·|), j(r) = ∫_0^r μ ([`prox_line`], [`prox_plane`]), which the
//! reduced solvers, the full-space Newton method and the velocity step all use.

use crate::problem::FrictionLaw;

/// max over nodes of the distance of −g_i to ω_i ∂j(|·|)(x_i) (Clarke subdifferential), for
/// `block` = d − 1 components per node (consecutive in `g` and `x`) and ω_i per node:
/// stick (x_i = 0): max(|g_i| − ω_i μ(0), 0); slip: |g_i + ω_i μ(|x_i|) x_i/|x_i||. In 3D
/// NaN if any violation is NaN.
pub fn kkt_violation(
    block: usize,
    g: &[f64],
    x: &[f64],
    weights: &[f64],
    law: &FrictionLaw,
) -> f64 {
    match block {
        1 => line_violation(g, x, weights, law),
        _ => plane_violation(g, x, weights, law),
    }
}

/// True when the load b of the Γ3 DOFs leaves every node at rest: |b_i| ≤ ω_i μ(0) for
/// every node i (the stick condition at x = 0 with g = −b), checked exactly.
pub fn all_stick(block: usize, b: &[f64], weights: &[f64], law: &FrictionLaw) -> bool {
    let mu0 = law.mu(0.0);
    match block {
        1 => b.iter().zip(weights).all(|(b, w)| b.abs() <= w * mu0),
        _ => b
            .chunks(block)
            .zip(weights)
            .all(|(b, w)| b.iter().map(|v| v * v).sum::<f64>().sqrt() <= w * mu0),
    }
}

/// One component per node.
fn line_violation(g: &[f64], x: &[f64], weights: &[f64], law: &FrictionLaw) -> f64 {
    g.iter()
        .zip(x)
        .zip(weights)
        .map(|((&gi, &xi), &w)| {
            if xi == 0.0 {
                (gi.abs() - w * law.mu(0.0)).max(0.0)
            } else {
                (gi + w * law.mu(xi.abs()) * xi.signum()).abs()
            }
        })
        .fold(0.0, f64::max)
}

/// Two components per node; NaN if any violation is NaN.
fn plane_violation(g: &[f64], x: &[f64], weights: &[f64], law: &FrictionLaw) -> f64 {
    weights
        .iter()
        .enumerate()
        .map(|(i, &w)| {
            let (gi, xi) = (node(g, i), node(x, i));
            if xi == [0.0, 0.0] {
                let excess = norm(gi) - w * law.mu(0.0);
                // (Not `max`, which would turn NaN into 0.)
                if excess > 0.0 || excess.is_nan() {
                    excess
                } else {
                    0.0
                }
            } else {
                let r = norm(xi);
                let f = w * law.mu(r) / r;
                norm([gi[0] + f * xi[0], gi[1] + f * xi[1]])
            }
        })
        .fold(0.0, |a: f64, v| {
            if a.is_nan() || v.is_nan() {
                f64::NAN
            } else {
                a.max(v)
            }
        })
}

/// prox of c·j(|·|) at z ∈ R (c > 0): 0 if |z| ≤ c μ(0), else sign(z)·r with r + c μ(r) = |z|.
/// Unique when 1 + c μ'(r) > 0 (guaranteed by the step size under the smallness condition).
pub fn prox_line(law: &FrictionLaw, c: f64, z: f64) -> f64 {
    let az = z.abs();
    if az <= c * law.mu(0.0) {
        return 0.0;
    }
    if let FrictionLaw::Tresca { g } = law {
        return z.signum() * (az - c * g);
    }
    // q(r) = r + c μ(r) − |z| is increasing with q(0) < 0 ≤ q(|z|): safeguarded Newton.
    let (mut lo, mut hi) = (0.0, az);
    let mut r = 0.5 * az;
    for _ in 0..200 {
        let q = r + c * law.mu(r) - az;
        if q.abs() <= 1e-15 * az {
            break;
        }
        if q < 0.0 {
            lo = r;
        } else {
            hi = r;
        }
        let dq = 1.0 + c * law.dmu(r);
        let newton = r - q / dq;
        r = if dq > 0.0 && newton > lo && newton < hi {
            newton
        } else {
            0.5 * (lo + hi)
        };
        if hi - lo <= 1e-16 * az {
            break;
        }
    }
    z.signum() * r
}

/// prox of c·j(|·|) at z ∈ R² (c ≥ 0), the block soft threshold: 0 if |z| ≤ c μ(0), else
/// (z/|z|)·r with r + c μ(r) = |z| (the scalar prox [`prox_line`] on |z|).
pub fn prox_plane(law: &FrictionLaw, c: f64, z: [f64; 2]) -> [f64; 2] {
    let az = norm(z);
    if az <= c * law.mu(0.0) {
        return [0.0, 0.0];
    }
    let r = prox_line(law, c, az);
    [z[0] / az * r, z[1] / az * r]
}

/// Node i's 2-vector of a DOF vector with two components per node.
pub fn node(v: &[f64], i: usize) -> [f64; 2] {
    [v[2 * i], v[2 * i + 1]]
}

/// The Euclidean norm of a 2-vector.
pub fn norm(v: [f64; 2]) -> f64 {
    v[0].hypot(v[1])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn laws() -> [FrictionLaw; 2] {
        [
            FrictionLaw::Tresca { g: 1.5 },
            FrictionLaw::SlipWeakening {
                mu0: 1.2,
                mu1: 0.4,
                alpha: 3.0,
            },
        ]
    }

    #[test]
    fn kkt_violation_by_hand() {
        let law = FrictionLaw::Tresca { g: 2.0 };
        let w = [1.0, 0.5];
        // Node 0 stuck with |g| = 5 > 2: violation 3. Node 1 slipping along (1, 0) with
        // g = (−1, 0.5): g + 0.5·2·(1, 0) = (0, 0.5).
        let g = [3.0, 4.0, -1.0, 0.5];
        let x = [0.0, 0.0, 2.0, 0.0];
        assert!((kkt_violation(2, &g, &x, &w, &law) - 3.0).abs() < 1e-15);
        let g = [0.6, 0.8, -1.0, 0.5];
        assert!((kkt_violation(2, &g, &x, &w, &law) - 0.5).abs() < 1e-15);
        let g = [0.6, 0.8, -1.0, 0.0];
        assert_eq!(kkt_violation(2, &g, &x, &w, &law), 0.0);
        let g = [f64::NAN, 0.8, -1.0, 0.0];
        assert!(kkt_violation(2, &g, &x, &w, &law).is_nan());
        // One component: stuck with |−5| − 2 = 3; slipping with −1.5 + 0.5·2 = −0.5.
        let (g, x) = ([-5.0, -1.5], [0.0, 3.0]);
        assert_eq!(kkt_violation(1, &g, &x, &w, &law), 3.0);
        let g = [1.0, -1.5];
        assert_eq!(kkt_violation(1, &g, &x, &w, &law), 0.5);
        let g = [1.0, -1.0];
        assert_eq!(kkt_violation(1, &g, &x, &w, &law), 0.0);
    }

    #[test]
    fn line_prox_solves_its_equation() {
        let law = &laws()[1];
        for &z in &[-3.0, -0.5, 0.1, 0.2, 2.0] {
            let c = 0.2; // c·c2 = 0.48 < 1
            let x = prox_line(law, c, z);
            if x == 0.0 {
                assert!(z.abs() <= c * 1.2);
            } else {
                assert!((x.abs() + c * law.mu(x.abs()) - z.abs()).abs() < 1e-13);
                assert_eq!(x.signum(), z.signum());
            }
        }
    }

    #[test]
    fn plane_prox_is_the_block_soft_threshold() {
        let c = 0.2; // c·c2 = 0.48 < 1
        for law in &laws() {
            for z in [[-3.0, 0.5], [0.1, -0.1], [0.2, 0.0], [1.0, 2.0], [0.0, 0.0]] {
                let y = prox_plane(law, c, z);
                let az = z[0].hypot(z[1]);
                if y == [0.0, 0.0] {
                    assert!(az <= c * law.mu(0.0), "{law:?} {z:?}");
                } else {
                    let r = y[0].hypot(y[1]);
                    assert!((r + c * law.mu(r) - az).abs() < 1e-13);
                    // Along z.
                    assert!((y[0] * z[1] - y[1] * z[0]).abs() < 1e-14 * az * r);
                    assert!(y[0] * z[0] + y[1] * z[1] > 0.0);
                }
                // The minimiser of c j(|y|) + ½ |y − z|² (convex for c c2 < 1).
                let f = |v: [f64; 2]| {
                    c * law.potential(v[0].hypot(v[1]))
                        + 0.5 * ((v[0] - z[0]).powi(2) + (v[1] - z[1]).powi(2))
                };
                for (dx, dy) in [(1e-4, 0.0), (0.0, 1e-4), (-1e-4, 1e-4), (1e-4, 1e-4)] {
                    assert!(f([y[0] + dx, y[1] + dy]) >= f(y) - 1e-15);
                }
            }
        }
    }

    /// Both proxes meet the node conditions they are the fixed point of: y = prox(z) means
    /// 0 ∈ (y − z)/c + ∂j(|·|)(y), the stick/slip conditions of a node of weight 1 with force
    /// residual g = (y − z)/c (violation zero to rounding).
    #[test]
    fn prox_points_meet_the_node_conditions() {
        for law in &laws() {
            for &c in &[0.05, 0.2, 0.4] {
                for k in 0..40 {
                    let z = [-4.0 + 0.21 * k as f64, 2.0 - 0.13 * k as f64];
                    let y = prox_plane(law, c, z);
                    let g = [(y[0] - z[0]) / c, (y[1] - z[1]) / c];
                    let v = kkt_violation(2, &g, &y, &[1.0], law);
                    assert!(v <= 1e-12 * (1.0 + norm(z) / c), "{law:?} {c} {z:?}: {v}");
                    let y1 = prox_line(law, c, z[0]);
                    let v1 = kkt_violation(1, &[(y1 - z[0]) / c], &[y1], &[1.0], law);
                    assert!(
                        v1 <= 1e-12 * (1.0 + z[0].abs() / c),
                        "{law:?} {c} {z:?}: {v1}"
                    );
                }
            }
        }
    }

    /// The exact stick test is the stick condition at x = 0 with the load as −g.
    #[test]
    fn stick_test_is_the_stick_condition_at_rest() {
        let law = FrictionLaw::Tresca { g: 1.0 };
        assert!(all_stick(1, &[1.0, -2.0], &[1.0, 2.0], &law));
        assert!(!all_stick(1, &[1.0, -2.5], &[1.0, 2.0], &law));
        assert!(all_stick(2, &[0.6, 0.8, 0.0, 2.0], &[1.0, 2.0], &law));
        assert!(!all_stick(2, &[0.6, 0.81, 0.0, 2.0], &[1.0, 2.0], &law));
        for b in [[0.3, -0.4], [1.2, 0.0], [0.0, 0.5]] {
            let at_rest = kkt_violation(2, &b.map(|v| -v), &[0.0, 0.0], &[0.5], &law) == 0.0;
            assert_eq!(all_stick(2, &b, &[0.5], &law), at_rest, "{b:?}");
        }
    }
}
