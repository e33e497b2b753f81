//! The velocity HVI (3.13) in 3D reduced to the tangential DOFs of the Γ3 nodes. Node i has a
//! tangential 2-vector x_i = (x_{2i}, x_{2i+1}) (its two tangential DOFs, consecutive), and
//! friction is isotropic:
//!
//!   minimise Φ(x) = ½ xᵀ S x − bᵀ x + Σ_i ω_i j(|x_i|),   x ∈ R^{2m},   j(r) = ∫_0^r μ(s) ds,
//!
//! with |·| the Euclidean norm, S (2m × 2m, dense, SPD) the Schur complement of the velocity
//! operator, b the reduced load and ω_i the nodal weights. The optimality (Clarke
//! stationarity) conditions are, per node, with g = S x − b and g_i its 2-vector at node i:
//!   stick:  x_i = 0  and |g_i| ≤ ω_i μ(0),
//!   slip:   x_i ≠ 0  and g_i + ω_i μ(|x_i|) x_i/|x_i| = 0.
//! Under the (discrete) smallness condition S − diag(ω c2τ) ≻ 0, Φ is strongly convex even
//! for non-convex j, so its stationary point is unique and is the minimiser. In 2D (one DOF per
//! node) this is [`super::friction_reduced`].
//!
//! Method: semismooth Newton on the fixed-point form of these conditions,
//!   x_i = prox_{c_i ω_i j}(z_i),   z_i = x_i − c_i g_i,   c_i = 2 / tr S_ii,
//! where prox_{c j}(z) = 0 if |z| ≤ c μ(0), else ρ ẑ with ρ + c μ(ρ) = |z| (block soft
//! threshold, [`prox`]) and S_ii is node i's 2 × 2 diagonal block; z_i/c_i = S_ii x_i − g_i is
//! the local force when S_ii is isotropic. Each iteration predicts the stick set
//! A = {i : |z_i| ≤ c_i ω_i μ(0)} and the slip set F (the rest), linearises the slip force at
//! the local prediction p_i = ρ_i ẑ_i,
//!   μ(|y|) y/|y| ≈ μ(ρ) ẑ + [μ'(ρ) ẑẑᵀ + μ(ρ)/ρ (I − ẑẑᵀ)] (y − ρ ẑ),
//! and takes the Newton point y with y_A = 0 and
//!   (S_FF + D) y_F = b_F − k_F,
//!   D_i = ω_i [μ'(ρ_i) ẑ_iẑ_iᵀ + μ(ρ_i)/ρ_i (I − ẑ_iẑ_iᵀ)],   k_i = ω_i (μ(ρ_i) − ρ_i μ'(ρ_i)) ẑ_i.
//! This is the semismooth Newton step of x − prox(x − C g) = 0 multiplied by the inverse of the
//! prox's Jacobian, which makes it symmetric. Linearising at p_i rather than at x_i gives every
//! slip node a direction, also where x_i = 0 (the direction of its local force). Since μ ≥ 0,
//! S_FF + D ≽ (S − diag(ω c2τ))_FF, positive definite under the smallness condition: y is one
//! Cholesky solve with the principal submatrix of S on the slip DOFs. For Tresca the slip
//! force is not linear in y, so, unlike 2D, a right partition still takes a few Newton steps.
//!
//! Globalisation as in 2D: candidate points are compared by Φ and the lowest is kept.
//! - The proximal-gradient point q = prox(x − g/L) (L ≥ λ_max(S), Gershgorin) always
//!   decreases Φ: global convergence.
//! - The Newton point above and its shortenings x + α (y − x), α = 1, ½, …: fast local
//!   convergence. When none beats q, slip nodes with y_i·ẑ_i ≤ 0 (the Newton point points
//!   against the slip it was linearised for) are moved to the stick set and y recomputed.
//! - Failing that, the segment from q towards the Newton point of q's own partition,
//!   linearised at q: a Newton direction of Φ restricted to {y_A = 0}, which is smooth and
//!   convex around q, hence a descent direction from q.
//!
//! Energy differences are formed from the step,
//!   Φ(x + d) − Φ(x) = dᵀ(g + ½ S d) + Σ_i ω_i ∫_{|x_i|}^{|x_i + d_i|} μ,
//! so that candidates can still be ranked near the solution, where the decreases are far
//! below the rounding of Φ itself.
//!
//! Cost per iteration: one Cholesky factorisation of the principal submatrix of S on the slip
//! DOFs (more only while Newton fails), two S products (g is updated, not recomputed) and
//! O(m) work per trial point. S is never copied.

use super::friction_node::{self, node, norm, prox_plane as prox};
use super::{SolveError, SolverReport, SolverSettings};
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt;
use faer::{Conj, Mat, MatMut, Par};

use super::reduced::mul;
pub use super::reduced::Reduced;

/// Solves the reduced problem from the warm start `x` (overwritten with the solution).
pub fn solve(
    p: &Reduced,
    x: &mut [f64],
    settings: &SolverSettings,
    step: usize,
) -> Result<SolverReport, SolveError> {
    let m = p.nodes();
    let n = 2 * m;
    assert!(
        p.s.nrows() == n && p.s.ncols() == n && p.b.len() == n && x.len() == n,
        "friction_isotropic: S must be 2m × 2m and b, x of length 2m for m = weights.len()"
    );
    if p.b.iter().all(|&v| v == 0.0) {
        // No load: x = 0 is stationary (g = 0 sticks), the unique stationary point under the
        // smallness condition. Set exactly, as a relative residual cannot judge it.
        x.iter_mut().for_each(|v| *v = 0.0);
        return Ok(SolverReport {
            iterations: 0,
            residual: 0.0,
            krylov_iterations: 0,
        });
    }
    let s = p.s.as_slice();
    // Lipschitz bound of ∇ of the smooth part (Gershgorin; S is symmetric, so column sums)
    // for the proximal-gradient step, and the local steps c_i = 2 / tr S_ii.
    let lip = (0..n)
        .map(|j| s[j * n..(j + 1) * n].iter().map(|v| v.abs()).sum::<f64>())
        .fold(f64::MIN_POSITIVE, f64::max);
    let local: Vec<f64> = (0..m)
        .map(|i| 2.0 / (s[2 * i * n + 2 * i] + s[(2 * i + 1) * n + 2 * i + 1]))
        .collect();
    let scale = p.scale();
    let mut g = p.gradient(x);
    // g is updated by S·(step) products; it is recomputed from x before convergence is
    // declared, so the accumulated rounding of the updates cannot fake a small residual.
    let mut fresh = true;
    let mut stalled = 0;
    let mut lowest = f64::INFINITY;
    let mut sd = vec![0.0; n];
    for it in 0..=settings.max_iterations {
        let mut residual = friction_node::kkt_violation(2, &g, x, p.weights, p.law) / scale;
        if residual <= settings.tolerance && !fresh {
            g = p.gradient(x);
            residual = friction_node::kkt_violation(2, &g, x, p.weights, p.law) / scale;
        }
        if residual <= settings.tolerance {
            return Ok(SolverReport {
                iterations: it,
                residual,
                krylov_iterations: 0,
            });
        }
        // Past the iteration limit, on non-finite data, or when stalled at working precision
        // (a tolerance below the rounding of S x − b): every further iteration would cost a
        // factorisation for nothing.
        if it == settings.max_iterations || !residual.is_finite() || stalled == STALL_LIMIT {
            return Err(SolveError::NotConverged {
                what: "velocity (friction) solver",
                step,
                iterations: it,
                residual,
                tolerance: settings.tolerance,
            });
        }
        // The proximal-gradient point q (as the step dq = q − x): the fallback, which always
        // decreases Φ.
        let c = 1.0 / lip;
        let mut dq = vec![0.0; n];
        for i in 0..m {
            let xi = node(x, i);
            let z = [xi[0] - c * g[2 * i], xi[1] - c * g[2 * i + 1]];
            let v = prox(p.law, c * p.weights[i], z);
            dq[2 * i] = v[0] - xi[0];
            dq[2 * i + 1] = v[1] - xi[1];
        }
        let mut sdq = vec![0.0; n];
        mul(p.s, &dq, &mut sdq);
        let mut best = Trial {
            change: energy_change(p, x, &g, &dq, &sdq),
            d: dq.clone(),
            sd: sdq.clone(),
        };
        // The semismooth Newton point on the locally predicted partition, shortened while it
        // does not beat q. When no point of the segment does, slip nodes whose Newton point
        // points against their linearisation direction (y_i·ẑ_i ≤ 0) contradict the slip
        // prediction: typically they stick at the solution while their local force is still
        // above the bound, and keeping them makes Newton overshoot through 0 again and again.
        // They are moved to the stick set and the point recomputed.
        let mut lin: Vec<Linearisation> = (0..m)
            .filter_map(|i| {
                let xi = node(x, i);
                let z = [xi[0] - local[i] * g[2 * i], xi[1] - local[i] * g[2 * i + 1]];
                Linearisation::local(p, i, local[i], z)
            })
            .collect();
        let mut newton_won = false;
        for _ in 0..NEWTON_ROUNDS {
            let Some(d) = newton_step(p, x, &g, &lin) else {
                break;
            };
            mul(p.s, &d, &mut sd);
            if search(p, x, &g, None, (&d, &sd), &mut best) {
                newton_won = true;
                break;
            }
            let before = lin.len();
            lin.retain(|l| {
                let i = l.node;
                let y = [x[2 * i] + d[2 * i], x[2 * i + 1] + d[2 * i + 1]];
                l.r == 0.0 || y[0] * l.dir[0] + y[1] * l.dir[1] > 0.0
            });
            if lin.len() == before {
                break;
            }
        }
        if !newton_won {
            // On the partition of q, the Newton step from q (linearised there) is a Newton
            // step for Φ restricted to {y_A = 0}, smooth and convex around q: a descent
            // direction, so the segment from q towards it improves on q.
            let lin: Vec<Linearisation> = (0..m)
                .filter_map(|i| {
                    let q = [x[2 * i] + dq[2 * i], x[2 * i + 1] + dq[2 * i + 1]];
                    Linearisation::at_point(p, i, q)
                })
                .collect();
            if let Some(d) = newton_step(p, x, &g, &lin) {
                mul(p.s, &d, &mut sd);
                search(p, x, &g, Some((&dq, &sdq)), (&d, &sd), &mut best);
            }
        }
        // Stalled: no better residual than before, and Φ decreasing by no more than its own
        // rounding (relative to the size of its terms).
        let size = 0.5 * dot(x, &g).abs() + 1.5 * dot(x, p.b).abs() + p.friction_energy(x);
        let noise = best.change >= -100.0 * f64::EPSILON * size;
        stalled = if residual >= lowest && noise {
            stalled + 1
        } else {
            0
        };
        lowest = lowest.min(residual);
        // A full step to a stuck node is x + (−x), exactly 0 as the stick test requires.
        for k in 0..n {
            x[k] += best.d[k];
            g[k] += best.sd[k];
        }
        fresh = false;
    }
    unreachable!()
}

/// Newton points tried per iteration on the local prediction (the first, then after each
/// removal of reversed slip nodes).
const NEWTON_ROUNDS: usize = 4;

/// Consecutive stalled iterations (see the loop) after which the solver gives up.
const STALL_LIMIT: usize = 5;

/// A trial point x + d, with S d and Φ(x + d) − Φ(x).
struct Trial {
    d: Vec<f64>,
    sd: Vec<f64>,
    change: f64,
}

/// Points tried on a segment: α = 1, ½, …, 2^(1 − HALVINGS). Each costs O(m) (the S
/// products of the segment's ends are combined), so shortening is cheap.
const HALVINGS: usize = 30;

/// Tries the points a + α (b − a) for α = 1, ½, … (`a`, `b` steps from x with their S
/// products; `a` None: x itself) and replaces `best` by the first that is lower in Φ.
/// Returns whether one was.
fn search(
    p: &Reduced,
    x: &[f64],
    g: &[f64],
    a: Option<(&[f64], &[f64])>,
    b: (&[f64], &[f64]),
    best: &mut Trial,
) -> bool {
    let n = x.len();
    let mut alpha = 1.0;
    for _ in 0..HALVINGS {
        // α = 1 is b itself, so its stuck nodes stay exactly 0.
        let (d, sd): (Vec<f64>, Vec<f64>) = if alpha == 1.0 {
            (b.0.to_vec(), b.1.to_vec())
        } else {
            (0..n)
                .map(|k| {
                    let (ad, asd) = a.map_or((0.0, 0.0), |(ad, asd)| (ad[k], asd[k]));
                    (ad + alpha * (b.0[k] - ad), asd + alpha * (b.1[k] - asd))
                })
                .unzip()
        };
        let change = energy_change(p, x, g, &d, &sd);
        if change < best.change {
            *best = Trial { d, sd, change };
            return true;
        }
        alpha *= 0.5;
    }
    false
}

/// A slip node's linearisation point ρ ẑ (|ẑ| = 1, ρ ≥ 0).
struct Linearisation {
    node: usize,
    dir: [f64; 2],
    r: f64,
}

impl Linearisation {
    /// Node i slips when the local prox at z = x_i − c g_i is nonzero; linearised there.
    /// Nodes without a friction threshold (ω_i μ(0) = 0) are smooth and always "slip".
    fn local(p: &Reduced, i: usize, c: f64, z: [f64; 2]) -> Option<Self> {
        let threshold = p.weights[i] * p.law.mu(0.0);
        let az = norm(z);
        if az <= c * threshold && threshold > 0.0 {
            return None;
        }
        Self::at_point(p, i, prox(p.law, c * p.weights[i], z))
    }

    /// Linearised at the point v; None (stick) when v = 0 and node i has a threshold.
    fn at_point(p: &Reduced, i: usize, v: [f64; 2]) -> Option<Self> {
        let r = norm(v);
        if r == 0.0 {
            // At 0 the slip force of a node without threshold is ω μ'(0) y to first order.
            return (p.weights[i] * p.law.mu(0.0) == 0.0).then_some(Linearisation {
                node: i,
                dir: [1.0, 0.0],
                r: 0.0,
            });
        }
        Some(Linearisation {
            node: i,
            dir: [v[0] / r, v[1] / r],
            r,
        })
    }

    /// D_i (symmetric 2 × 2) and k_i of the linearised slip force D_i y + k_i.
    fn terms(&self, p: &Reduced) -> ([[f64; 2]; 2], [f64; 2]) {
        let w = p.weights[self.node];
        let (mu, dmu) = (p.law.mu(self.r), p.law.dmu(self.r));
        let [u, v] = self.dir;
        if self.r == 0.0 {
            return ([[w * dmu, 0.0], [0.0, w * dmu]], [0.0, 0.0]);
        }
        // ω [μ' ẑẑᵀ + μ/ρ (I − ẑẑᵀ)] = ω [(μ' − μ/ρ) ẑẑᵀ + μ/ρ I].
        let t = mu / self.r;
        let a = dmu - t;
        let d = [
            [w * (a * u * u + t), w * a * u * v],
            [w * a * u * v, w * (a * v * v + t)],
        ];
        let k = w * (mu - self.r * dmu);
        (d, [k * u, k * v])
    }
}

/// The Newton point y for the slip set and linearisation points `lin` (every other node
/// stuck: y_i = 0), returned as the step y − x. Solved for the correction δ = y_F − x_F,
///   (S_FF + D) δ = −g_F − k_F − D x_F + S_FA x_A,
/// whose rounding shrinks with the step. None when S_FF + D is not numerically positive
/// definite (possible only without the smallness condition).
fn newton_step(p: &Reduced, x: &[f64], g: &[f64], lin: &[Linearisation]) -> Option<Vec<f64>> {
    let n = x.len();
    let mut step: Vec<f64> = x.iter().map(|v| -v).collect();
    if lin.is_empty() {
        return Some(step);
    }
    let s = p.s.as_slice();
    let dofs: Vec<usize> = lin
        .iter()
        .flat_map(|l| [2 * l.node, 2 * l.node + 1])
        .collect();
    let nf = dofs.len();
    // The lower triangle of S_FF + D (read column by column from S's column-major storage).
    let mut jac = Mat::<f64>::zeros(nf, nf);
    for (b, &cb) in dofs.iter().enumerate() {
        let col = &s[cb * n..(cb + 1) * n];
        let out = jac.col_as_slice_mut(b);
        for a in b..nf {
            out[a] = col[dofs[a]];
        }
    }
    let mut rhs: Vec<f64> = dofs.iter().map(|&k| -g[k]).collect();
    for (e, l) in lin.iter().enumerate() {
        let (d, k) = l.terms(p);
        let xi = node(x, l.node);
        for r in 0..2 {
            rhs[2 * e + r] -= k[r] + d[r][0] * xi[0] + d[r][1] * xi[1];
        }
        jac[(2 * e, 2 * e)] += d[0][0];
        jac[(2 * e + 1, 2 * e)] += d[1][0];
        jac[(2 * e + 1, 2 * e + 1)] += d[1][1];
    }
    // + S_FA x_A: the stuck nodes that move to 0 (columns of S, contiguous).
    let mut slip = vec![false; n / 2];
    lin.iter().for_each(|l| slip[l.node] = true);
    for col in 0..n {
        if !slip[col / 2] && x[col] != 0.0 {
            let c = &s[col * n..(col + 1) * n];
            for (r, &k) in rhs.iter_mut().zip(&dofs) {
                *r += c[k] * x[col];
            }
        }
    }
    let par = Par::Seq;
    let mut mem = MemBuffer::new(llt::factor::cholesky_in_place_scratch::<f64>(
        nf,
        par,
        Default::default(),
    ));
    llt::factor::cholesky_in_place(
        jac.as_mut(),
        Default::default(),
        par,
        MemStack::new(&mut mem),
        Default::default(),
    )
    .ok()?;
    let mut none = MemBuffer::new(StackReq::EMPTY);
    llt::solve::solve_in_place_with_conj(
        jac.as_ref(),
        Conj::No,
        MatMut::from_column_major_slice_mut(&mut rhs, nf, 1),
        par,
        MemStack::new(&mut none),
    );
    for (&k, delta) in dofs.iter().zip(&rhs) {
        step[k] = *delta;
    }
    Some(step)
}

/// Φ(x + d) − Φ(x) from g = S x − b and S d. Formed from the step, not as a difference of
/// two values of Φ, whose cancellation would hide the small decreases near the solution.
fn energy_change(p: &Reduced, x: &[f64], g: &[f64], d: &[f64], sd: &[f64]) -> f64 {
    let quadratic: f64 = d
        .iter()
        .zip(g)
        .zip(sd)
        .map(|((d, g), sd)| d * (g + 0.5 * sd))
        .sum();
    let friction: f64 = (0..p.nodes())
        .filter(|&i| p.weights[i] != 0.0)
        .map(|i| {
            let xi = node(x, i);
            let di = [d[2 * i], d[2 * i + 1]];
            let yi = [xi[0] + di[0], xi[1] + di[1]];
            let (r0, r1) = (norm(xi), norm(yi));
            // |y| − |x| = (y − x)·(y + x) / (|y| + |x|), without cancellation.
            let dr = if r0 + r1 > 0.0 {
                (di[0] * (xi[0] + yi[0]) + di[1] * (xi[1] + yi[1])) / (r0 + r1)
            } else {
                0.0
            };
            let change = p.law.potential_change(r0, r1, dr);
            p.weights[i] * change
        })
        .sum();
    quadratic + friction
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(a, b)| a * b).sum()
}

#[cfg(test)]
mod tests;
