//! Where a slipping velocity step on the multigrid path starts: the minimiser of the step's
//! energy (3.13) over the span of the earlier steps' velocities.
//!
//! With W = [w̃_1 … w̃_l] K-orthonormal over the free DOFs ([`SolutionSpace`]) and w = W c,
//!   Ê(c) = E(W c) = ½ cᵀc − bᵀc + Σ_i ω_i j(|A_i c|),   b = Wᵀ f,
//! where A_i ((d − 1) × l) holds node i's tangential rows of W. This is Fischer's projection
//! ([`crate::linalg::projection`]) carried over to the non-smooth energy; for a step whose Γ3
//! sticks it is that projection. Ê is minimised by Newton's method with a line search on Ê:
//!   gradient  c − b + Σ_i ω_i μ(ρ_i) A_iᵀ ẑ_i,
//!   Hessian   I + Σ_i A_iᵀ E_i A_i,
//! with ρ_i = |A_i c|, ẑ_i = A_i c / ρ_i and E_i the slip block of
//! [`super::semismooth_newton`] (nodes at ρ_i = 0 contribute neither). An iteration costs
//! O(l² · nodes whose rows of W are not zero) and no product with K.
//!
//! It starts from the coordinates of the newest solution in the span (the last step's
//! velocity), and every accepted step lowers Ê, so the guess is never worse in energy than
//! that velocity. The Newton method on all free DOFs still runs to the step's tolerance from
//! here: the guess decides only where it starts.

use crate::linalg::projection::SolutionSpace;
use crate::problem::FrictionLaw;
use nalgebra::{DMatrix, DVector};

/// Most Newton iterations on Ê (each costs next to nothing; a node that sticks at the
/// minimiser but not in every basis vector makes Ê non-smooth there and slows them).
const MAX_ITERATIONS: usize = 30;
/// Most halvings of a line search.
const HALVINGS: usize = 40;
/// Stop when the gradient of Ê is this small relative to ‖b‖∞.
const GRADIENT_TOLERANCE: f64 = 1e-14;

/// The Γ3 layout of the free DOFs: interior first, then `block` = d − 1 tangential DOFs per
/// Γ3 node with weight ω_i.
pub struct Contact<'a> {
    pub n_interior: usize,
    pub block: usize,
    pub weights: &'a [f64],
    pub law: &'a FrictionLaw,
}

/// Node i's rows A_i of W (row-major, `block` × l) for each Γ3 node where W is not zero.
struct NodeRows {
    node: usize,
    rows: Vec<f64>,
}

/// w ← W c* with c* the minimiser found of Ê for the free-DOF load `f`; the space records it
/// as the guess its next `extend` measures from. Returns the Newton iterations taken, or None
/// (w untouched) when the space is empty.
pub fn minimise(
    space: &mut SolutionSpace,
    f: &[f64],
    contact: &Contact,
    w: &mut [f64],
) -> Option<usize> {
    let mut c = space.newest()?;
    let l = c.len();
    if l == 0 {
        return None;
    }
    let b = space.coordinates(f);
    let nodes = node_rows(space.basis(), contact);
    let scale = b.iter().fold(f64::MIN_POSITIVE, |m, v| m.max(v.abs()));
    let mut iterations = 0;
    for _ in 0..MAX_ITERATIONS {
        let (gradient, hessian) = linearise(&c, &b, &nodes, contact);
        if gradient.amax() <= GRADIENT_TOLERANCE * scale {
            break;
        }
        let d = match hessian.cholesky() {
            Some(ch) => ch.solve(&(-&gradient)),
            None => -&gradient,
        };
        iterations += 1;
        let Some(alpha) = line_search(&c, &b, &d, &nodes, contact) else {
            break;
        };
        c.iter_mut()
            .zip(d.iter())
            .for_each(|(c, d)| *c += alpha * d);
    }
    space.combine(&c, w);
    Some(iterations)
}

fn node_rows(basis: &[Vec<f64>], contact: &Contact) -> Vec<NodeRows> {
    let (l, block) = (basis.len(), contact.block);
    (0..contact.weights.len())
        .filter(|&i| contact.weights[i] != 0.0)
        .filter_map(|i| {
            let start = contact.n_interior + block * i;
            let mut rows = vec![0.0; block * l];
            for (j, v) in basis.iter().enumerate() {
                for r in 0..block {
                    rows[r * l + j] = v[start + r];
                }
            }
            rows.iter()
                .any(|&v| v != 0.0)
                .then_some(NodeRows { node: i, rows })
        })
        .collect()
}

/// x = A_i c (the node's tangential velocity), padded to 2 entries.
fn apply(rows: &[f64], block: usize, c: &[f64]) -> [f64; 2] {
    let l = c.len();
    let mut x = [0.0; 2];
    for (r, x) in x.iter_mut().enumerate().take(block) {
        *x = rows[r * l..(r + 1) * l]
            .iter()
            .zip(c)
            .map(|(a, c)| a * c)
            .sum();
    }
    x
}

/// Gradient and Hessian of Ê at c.
fn linearise(
    c: &[f64],
    b: &[f64],
    nodes: &[NodeRows],
    contact: &Contact,
) -> (DVector<f64>, DMatrix<f64>) {
    let (l, block, law) = (c.len(), contact.block, contact.law);
    let mut gradient = DVector::from_iterator(l, c.iter().zip(b).map(|(c, b)| c - b));
    let mut hessian = DMatrix::<f64>::identity(l, l);
    for node in nodes {
        let x = apply(&node.rows, block, c);
        let rho = x[0].hypot(x[1]);
        if rho == 0.0 {
            continue;
        }
        let om = contact.weights[node.node];
        let (mu, dmu) = (law.mu(rho), law.dmu(rho));
        let z = [x[0] / rho, x[1] / rho];
        // E_i (block × block) = ω [μ′ ẑẑᵀ + μ/ρ (I − ẑẑᵀ)]; in 2D ω μ′.
        let mut e = [[0.0; 2]; 2];
        for (p, e) in e.iter_mut().enumerate().take(block) {
            for (q, e) in e.iter_mut().enumerate().take(block) {
                let zz = z[p] * z[q];
                let id = if p == q { 1.0 } else { 0.0 };
                *e = om
                    * (dmu * zz
                        + if block == 1 {
                            0.0
                        } else {
                            mu / rho * (id - zz)
                        });
            }
        }
        let a = |r: usize, j: usize| node.rows[r * l + j];
        for j in 0..l {
            gradient[j] += om * mu * (0..block).map(|r| a(r, j) * z[r]).sum::<f64>();
            // (E A)_{r j}, then (Aᵀ E A)_{k j}.
            let ea: [f64; 2] =
                std::array::from_fn(|p| (0..block).map(|q| e[p][q] * a(q, j)).sum::<f64>());
            for k in 0..l {
                hessian[(k, j)] += (0..block).map(|p| a(p, k) * ea[p]).sum::<f64>();
            }
        }
    }
    (gradient, hessian)
}

/// α = 1, ½, … until Ê(c + α d) < Ê(c), the change formed from the step (not as a difference
/// of two energies, so that it can be judged near the minimiser).
fn line_search(
    c: &[f64],
    b: &[f64],
    d: &DVector<f64>,
    nodes: &[NodeRows],
    contact: &Contact,
) -> Option<f64> {
    let block = contact.block;
    let slope: f64 = d
        .iter()
        .zip(c.iter().zip(b))
        .map(|(d, (c, b))| d * (c - b))
        .sum();
    let dd = d.norm_squared();
    let moves: Vec<([f64; 2], [f64; 2], f64)> = nodes
        .iter()
        .map(|node| {
            (
                apply(&node.rows, block, c),
                apply(&node.rows, block, d.as_slice()),
                contact.weights[node.node],
            )
        })
        .collect();
    let mut alpha = 1.0;
    for _ in 0..HALVINGS {
        let friction: f64 = moves
            .iter()
            .map(|(x, dx, om)| {
                om * contact
                    .law
                    .node_potential_change(*x, [alpha * dx[0], alpha * dx[1]])
            })
            .sum();
        if alpha * slope + 0.5 * alpha * alpha * dd + friction < 0.0 {
            return Some(alpha);
        }
        alpha *= 0.5;
    }
    None
}

#[cfg(test)]
mod tests;
