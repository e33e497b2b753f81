//! A residual a posteriori error estimator of one step of the fully discrete scheme,
//! computed from what the step has: w_n, w_{n−1}, B_{n−1}, ε(u_{n−1}), ζ_{n−1} and ζ_n.
//! The derivation, its assumptions and references are in
//! docs/src/explanation/a-posteriori.md.
//!
//! With σ_T = A ε(w_n)|_T + B_{n−1}|_T the P0 stress of (3.8), h_T the longest edge of cell
//! T and h_F that of facet F, the squared indicators of cell T at step n are
//!
//! velocity (3.13), in units of |·|_V (each residual divided by m_A = 2η):
//! - element:  h_T² ‖f0(t_n) + Div σ_h‖²_T = h_T² ‖f0(t_n)‖²_T (σ_h is constant on T);
//! - jump:     ½ Σ_{F ⊂ ∂T interior} h_F ‖[σ_h] ν_F‖²_F;
//! - traction: Σ_{F ⊂ ∂T ∩ Γ2} h_F ‖f2(t_n) − σ_T ν_F‖²_F;
//! - friction: Σ_{F ⊂ ∂T ∩ Γ3} h_F Σ_{i ∈ F} (|F|/d) dist(−σ_{τ,i}, ∂j(w_{τ,i}))², with
//!   σ_{τ,i} = σ_T ν_F − (n_i · σ_T ν_F) n_i the tangential traction in node i's frame and
//!   ∂j the Clarke subdifferential of the friction potential (the HVI's own residual;
//!   nodes of Γ1 carry none);
//! - time:     ‖ε(w_n − w_{n−1})‖²_T (zero at n = 1: the scheme has no w_0);
//!
//! damage (3.10), in units of κ^½ ‖∇·‖, with r = φ(ε(u_{n−1}), ζ_{n−1}) − (ζ_n − ζ_{n−1})/k
//! at the cell's quadrature points (those of the damage source), set to max(r, 0) where
//! ζ_n = 0 and min(r, 0) where ζ_n = 1 (there the obstacle takes up the rest, ∂I_{[0,1]}):
//! - element:  (h_T²/κ) ‖r‖²_T;
//! - jump:     ½ Σ_{F ⊂ ∂T interior} h_F κ ‖[∇ζ_n] · ν_F‖²_F, plus the whole facet
//!   h_F κ ‖∇ζ_n · ν_F‖²_F on ∂Ω (∂ζ/∂ν = 0);
//! - time:     κ ‖∇(ζ_n − ζ_{n−1})‖²_T.
//!
//! A step's part is the square root of its sum over the cells; the cell indicator η_T is the
//! square root of the sum of T's eight squared indicators.

#![allow(clippy::needless_range_loop)] // Index loops over vertices and components spell out the formulas.

use crate::fem::loads::cell_rule;
use crate::fem::{CellTensors, Geometry};
use crate::laws::constitutive::viscous_stress;
use crate::laws::damage_source::phi;
use crate::laws::Tensor;
use crate::linalg::par;
use crate::mesh::Mesh;
use crate::problem::{BoundaryKind, Problem};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// The parts of an estimate: of one step (square roots of sums over cells) or of a run
/// ((k Σ_n η_n²)^½ of each part, the L²(0, T) norm of the piecewise constant in time
/// indicators).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Parts {
    /// All parts together: (Σ of the squares)^½.
    pub total: f64,
    pub velocity: VelocityParts,
    /// None without damage.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub damage: Option<DamageParts>,
    /// The velocity's estimate (its five parts) relative to |w_h|_V (per step) or to
    /// (k Σ_n |w_n|²_V)^½ (per run): the quantity an accuracy target is compared with.
    pub relative_w: f64,
}

/// The velocity's parts, see the module docs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct VelocityParts {
    pub total: f64,
    pub element: f64,
    pub jump: f64,
    pub traction: f64,
    pub friction: f64,
    pub time: f64,
}

/// The damage's parts, see the module docs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct DamageParts {
    pub total: f64,
    pub element: f64,
    pub jump: f64,
    pub time: f64,
}

/// One step's estimate: the cell indicators η_T, their spatial velocity parts (the square
/// root of the element, jump, traction and friction squares: what an adaptive study marks
/// by, since refining the mesh does not reduce the time part) and the parts.
#[derive(Debug, Clone, PartialEq)]
pub struct StepEstimate {
    pub cells: Vec<f64>,
    pub velocity: Vec<f64>,
    pub parts: Parts,
}

/// What the estimate of step n reads (global nodal vectors, interleaved; per-cell tensors).
pub struct StepData<'a, const D: usize> {
    pub t: f64,
    pub k: f64,
    /// m_A of (2.31).
    pub m_a: f64,
    pub w: &'a [f64],
    /// w_{n−1}; None at n = 1.
    pub w_prev: Option<&'a [f64]>,
    /// B_{n−1} per cell, and u_{n−1} (global, interleaved).
    pub b: &'a CellTensors<D>,
    pub u_prev: &'a [f64],
    pub zeta_prev: &'a [f64],
    pub zeta: &'a [f64],
}

/// An interior facet: the two cells it separates and its geometry.
#[derive(Debug, Clone, Copy)]
struct Interior<const D: usize> {
    cells: [usize; 2],
    /// Unit normal pointing from `cells[0]` into `cells[1]`.
    normal: [f64; D],
    measure: f64,
    h: f64,
}

/// The estimator's mesh data, built once per mesh in O(N): interior facets, the cell of
/// every boundary facet, h_T, Γ3 node frames and Γ1 nodes.
pub struct Estimator<const D: usize> {
    interior: Vec<Interior<D>>,
    /// The cell each boundary facet (`Mesh::facets`) bounds, and the facet's h_F.
    owner: Vec<usize>,
    facet_h: Vec<f64>,
    h: Vec<f64>,
    /// n_i of every Γ3 node that is not clamped (node → unit normal, SCHEME.md's frames).
    frames: HashMap<usize, [f64; D]>,
}

/// The longest edge of the simplex with vertices `v`.
fn diameter<const D: usize>(v: &[usize], nodes: &[[f64; D]]) -> f64 {
    let mut h2: f64 = 0.0;
    for a in 0..v.len() {
        for b in a + 1..v.len() {
            let d2 = (0..D)
                .map(|c| (nodes[v[a]][c] - nodes[v[b]][c]).powi(2))
                .sum();
            h2 = h2.max(d2);
        }
    }
    h2.sqrt()
}

fn dot<const D: usize>(a: &[f64; D], b: &[f64; D]) -> f64 {
    (0..D).map(|c| a[c] * b[c]).sum()
}

fn mul<const D: usize>(s: &Tensor<D>, n: &[f64; D]) -> [f64; D] {
    std::array::from_fn(|i| (0..D).map(|j| s[(i, j)] * n[j]).sum())
}

/// The distance from −σ_τ to ∂j(w_τ) (the Clarke subdifferential of
/// j(ξ) = ∫_0^|ξ| μ(r) dr): |−σ_τ − μ(|w_τ|) w_τ/|w_τ|| where the node slips, and
/// max(|σ_τ| − μ(0), 0) where it sticks. Vectors in any common basis.
pub fn friction_residual<const D: usize>(
    law: &crate::problem::FrictionLaw,
    sigma_tau: &[f64; D],
    w_tau: &[f64; D],
) -> f64 {
    let speed = dot(w_tau, w_tau).sqrt();
    if speed == 0.0 {
        return (dot(sigma_tau, sigma_tau).sqrt() - law.mu(0.0)).max(0.0);
    }
    let mu = law.mu(speed);
    let r: [f64; D] = std::array::from_fn(|c| -sigma_tau[c] - mu * w_tau[c] / speed);
    dot(&r, &r).sqrt()
}

/// The damage VI's strong residual r masked by the obstacle: where ζ = 0 the VI lets
/// r ≤ 0 stand (∂I_{[0,1]}(0) = (−∞, 0]), where ζ = 1 it lets r ≥ 0 stand.
pub fn obstacle_residual(r: f64, zeta: f64) -> f64 {
    if zeta <= 0.0 {
        r.max(0.0)
    } else if zeta >= 1.0 {
        r.min(0.0)
    } else {
        r
    }
}

impl<const D: usize> Estimator<D> {
    /// The mesh data of `mesh` with the boundary parts of `problem`.
    pub fn new(problem: &Problem, mesh: &Mesh<D>, geo: &Geometry<D>) -> Estimator<D> {
        let key = |cell: &[usize], skip: usize| -> [usize; 3] {
            let mut k = [usize::MAX; 3];
            let mut m = 0;
            for (a, &n) in cell.iter().enumerate() {
                if a != skip {
                    k[m] = n;
                    m += 1;
                }
            }
            k[..D].sort_unstable();
            k
        };
        let mut first: HashMap<[usize; 3], (usize, usize)> =
            HashMap::with_capacity(mesh.n_cells() * (D + 1) / 2 + mesh.facets.len());
        let mut interior = Vec::with_capacity(mesh.n_cells() * (D + 1) / 2);
        for (e, cell) in mesh.cells().enumerate() {
            for a in 0..=D {
                let k = key(cell, a);
                match first.remove(&k) {
                    None => {
                        first.insert(k, (e, a));
                    }
                    Some((e0, a0)) => {
                        // ∇ψ_a = −|F_a| ν_a / (d |T|): the facet opposite vertex a, its
                        // outward normal and measure from the cell's gradients.
                        let g = geo.grad(e0, a0);
                        let len = dot(&g, &g).sqrt();
                        interior.push(Interior {
                            cells: [e0, e],
                            normal: std::array::from_fn(|c| -g[c] / len),
                            measure: D as f64 * geo.measure(e0) * len,
                            h: diameter(&k[..D], &mesh.nodes),
                        });
                    }
                }
            }
        }
        let owner = mesh
            .facets
            .iter()
            .map(|f| {
                let mut k = [usize::MAX; 3];
                k[..D].copy_from_slice(&f.nodes);
                k[..D].sort_unstable();
                first.get(&k).map_or(usize::MAX, |&(e, _)| e)
            })
            .collect();
        let facet_h = mesh
            .facets
            .iter()
            .map(|f| diameter(&f.nodes, &mesh.nodes))
            .collect();
        let h = mesh.cells().map(|c| diameter(c, &mesh.nodes)).collect();
        let kind = |f: &crate::mesh::Facet<D>| f.part.map(|p| &problem.boundary[p].kind);
        let mut clamped = vec![false; mesh.n_nodes()];
        let mut sums: HashMap<usize, [f64; D]> = HashMap::new();
        for f in &mesh.facets {
            match kind(f) {
                Some(BoundaryKind::Clamped) => f.nodes.iter().for_each(|&n| clamped[n] = true),
                Some(BoundaryKind::Contact) => {
                    for &n in &f.nodes {
                        let s = sums.entry(n).or_insert([0.0; D]);
                        (0..D).for_each(|c| s[c] += f.measure * f.normal[c]);
                    }
                }
                _ => {}
            }
        }
        let frames = sums
            .into_iter()
            .filter(|(n, _)| !clamped[*n])
            .map(|(n, s)| {
                let len = dot(&s, &s).sqrt();
                (n, std::array::from_fn(|c| s[c] / len))
            })
            .collect();
        Estimator {
            interior,
            owner,
            facet_h,
            h,
            frames,
        }
    }

    /// The estimate of one step (module docs).
    pub fn step(
        &self,
        problem: &Problem,
        mesh: &Mesh<D>,
        geo: &Geometry<D>,
        s: &StepData<D>,
    ) -> StepEstimate {
        let nc = mesh.n_cells();
        let inv_ma2 = 1.0 / (s.m_a * s.m_a);
        // Per cell: σ_T, and the squared velocity element and time indicators.
        // One pass over the cells: σ_T, ∇ζ_n, |T| |ε(w_n)|² and the cell's own indicators.
        let rule = cell_rule(D);
        let f0 = &problem.body_force;
        let damage = problem.damage.as_ref();
        let mut cells = vec![Cell::<D>::default(); nc];
        par::for_each_chunk_mut(&mut cells, par::ROW_CHUNK, |first, out| {
            for (i, c) in out.iter_mut().enumerate() {
                let e = first + i;
                let cell = mesh.cell(e);
                let (vol, h) = (geo.measure(e), self.h[e]);
                let eps_w = geo.strain(mesh, e, s.w);
                c.sigma = viscous_stress(&problem.material.viscosity, &eps_w) + s.b.get(e);
                c.w2 = vol * eps_w.norm_squared();
                let p = &mut c.parts;
                if !f0.is_zero() {
                    let f2: f64 = rule
                        .iter()
                        .map(|(l, wq)| {
                            let f = f0.at(&point(cell, &mesh.nodes, l), s.t);
                            wq * vol * dot(&f, &f)
                        })
                        .sum();
                    p[0] = h * h * f2 * inv_ma2;
                }
                if let Some(prev) = s.w_prev {
                    let d = eps_w - geo.strain(mesh, e, prev);
                    p[4] = vol * d.norm_squared();
                }
                if let Some(dm) = damage {
                    let eps_u = geo.strain(mesh, e, s.u_prev);
                    let r2: f64 = rule
                        .iter()
                        .map(|(l, wq)| {
                            let at = |z: &[f64]| -> f64 {
                                cell.iter().enumerate().map(|(a, &n)| l[a] * z[n]).sum()
                            };
                            let (zp, zn) = (at(s.zeta_prev), at(s.zeta));
                            let r = phi(&dm.source, &eps_u, zp) - (zn - zp) / s.k;
                            wq * vol * obstacle_residual(r, zn).powi(2)
                        })
                        .sum();
                    p[5] = h * h * r2 / dm.kappa;
                    let dz = gradient(&geo.grads(e), cell, s.zeta, s.zeta_prev);
                    p[7] = dm.kappa * vol * dot(&dz, &dz);
                    c.grad = gradient(&geo.grads(e), cell, s.zeta, &[]);
                }
            }
        });
        for f in &self.interior {
            let [a, b] = f.cells;
            let jump = mul(&(cells[a].sigma - cells[b].sigma), &f.normal);
            let v = 0.5 * f.h * f.measure * dot(&jump, &jump) * inv_ma2;
            cells[a].parts[1] += v;
            cells[b].parts[1] += v;
            if let Some(dm) = damage {
                let j = dot(&cells[a].grad, &f.normal) - dot(&cells[b].grad, &f.normal);
                let v = 0.5 * f.h * f.measure * dm.kappa * j * j;
                cells[a].parts[6] += v;
                cells[b].parts[6] += v;
            }
        }
        let facet_rule = cell_rule(D - 1);
        for (fi, f) in mesh.facets.iter().enumerate() {
            // Every boundary facet bounds a cell (the mesh found them so); none is skipped.
            let Some(c) = cells.get_mut(self.owner[fi]) else {
                continue;
            };
            let hf = self.facet_h[fi];
            if let Some(dm) = damage {
                let g = dot(&c.grad, &f.normal);
                c.parts[6] += hf * f.measure * dm.kappa * g * g;
            }
            let traction = mul(&c.sigma, &f.normal);
            match f.part.map(|p| &problem.boundary[p].kind) {
                Some(BoundaryKind::Clamped) => {}
                Some(BoundaryKind::Contact) => {
                    let mut r2 = 0.0;
                    for &n in &f.nodes {
                        let Some(nu) = self.frames.get(&n) else {
                            continue;
                        };
                        let tangential = |v: [f64; D]| -> [f64; D] {
                            let vn = dot(nu, &v);
                            std::array::from_fn(|c| v[c] - vn * nu[c])
                        };
                        let w_tau = tangential(std::array::from_fn(|c| s.w[D * n + c]));
                        let r = friction_residual(&problem.friction, &tangential(traction), &w_tau);
                        r2 += f.measure / D as f64 * r * r;
                    }
                    c.parts[3] += hf * r2 * inv_ma2;
                }
                kind => {
                    // Γ2, or traction-free (f2 = 0).
                    let f2 = match kind {
                        Some(BoundaryKind::Traction(f2)) if !f2.is_zero() => Some(f2),
                        _ => None,
                    };
                    let r2: f64 = facet_rule
                        .iter()
                        .map(|(l, wq)| {
                            let g = f2.map_or([0.0; D], |f2| {
                                f2.at(&point(&f.nodes, &mesh.nodes, l), s.t)
                            });
                            let r: [f64; D] = std::array::from_fn(|c| g[c] - traction[c]);
                            wq * f.measure * dot(&r, &r)
                        })
                        .sum();
                    c.parts[2] += hf * r2 * inv_ma2;
                }
            }
        }
        finish(&cells, damage.is_some())
    }
}

/// The point with barycentric coordinates `l` in the simplex with vertices `v`.
fn point<const D: usize>(v: &[usize], nodes: &[[f64; D]], l: &[f64; 4]) -> [f64; D] {
    std::array::from_fn(|c| v.iter().enumerate().map(|(a, &n)| l[a] * nodes[n][c]).sum())
}

/// ∇(z − z_prev) on a cell with basis gradients `g` (∇z alone when `z_prev` is empty).
fn gradient<const D: usize>(g: &[[f64; D]], cell: &[usize], z: &[f64], z_prev: &[f64]) -> [f64; D] {
    let mut out = [0.0; D];
    for (a, &n) in cell.iter().enumerate() {
        let v = z[n] - z_prev.get(n).copied().unwrap_or(0.0);
        (0..D).for_each(|c| out[c] += v * g[a][c]);
    }
    out
}

/// What the estimate keeps of a cell during a step.
#[derive(Clone, Copy)]
struct Cell<const D: usize> {
    /// σ_T = A ε(w_n) + B_{n−1}.
    sigma: Tensor<D>,
    /// ∇ζ_n on T (with damage).
    grad: [f64; D],
    /// |T| |ε(w_n)|², for |w_h|_V.
    w2: f64,
    /// The squared indicators: [element, jump, traction, friction, time] of the velocity,
    /// [element, jump, time] of the damage.
    parts: [f64; 8],
}

impl<const D: usize> Default for Cell<D> {
    fn default() -> Self {
        Cell {
            sigma: Tensor::zeros(),
            grad: [0.0; D],
            w2: 0.0,
            parts: [0.0; 8],
        }
    }
}

/// The cell indicators and the step's parts from the cells' squared indicators, with
/// |w_h|²_V for the relative velocity estimate. Sums run in cell order: the same bits for
/// any thread count.
fn finish<const D: usize>(cells: &[Cell<D>], damage: bool) -> StepEstimate {
    let mut sum = [0.0; 8];
    let mut w_v2 = 0.0;
    for c in cells {
        (0..8).for_each(|i| sum[i] += c.parts[i]);
        w_v2 += c.w2;
    }
    StepEstimate {
        cells: cells
            .iter()
            .map(|c| c.parts.iter().sum::<f64>().sqrt())
            .collect(),
        velocity: cells
            .iter()
            .map(|c| c.parts[..4].iter().sum::<f64>().sqrt())
            .collect(),
        parts: Parts::from_squares(&sum, w_v2, damage),
    }
}

impl Parts {
    /// The parts from the sums of their squares (the order of [`finish`]) and |w_h|²_V.
    fn from_squares(sq: &[f64; 8], w_v2: f64, damage: bool) -> Parts {
        let v2: f64 = sq[..5].iter().sum();
        let d2: f64 = sq[5..].iter().sum();
        Parts {
            total: (v2 + d2).sqrt(),
            velocity: VelocityParts {
                total: v2.sqrt(),
                element: sq[0].sqrt(),
                jump: sq[1].sqrt(),
                traction: sq[2].sqrt(),
                friction: sq[3].sqrt(),
                time: sq[4].sqrt(),
            },
            damage: damage.then(|| DamageParts {
                total: d2.sqrt(),
                element: sq[5].sqrt(),
                jump: sq[6].sqrt(),
                time: sq[7].sqrt(),
            }),
            relative_w: relative(v2.sqrt(), w_v2.sqrt()),
        }
    }

    /// The squares of the parts, in the order of [`finish`].
    fn squares(&self) -> [f64; 8] {
        let v = &self.velocity;
        let d = self.damage.unwrap_or_default();
        [
            v.element, v.jump, v.traction, v.friction, v.time, d.element, d.jump, d.time,
        ]
        .map(|x| x * x)
    }
}

/// η / |w|, and 0 for a zero estimate of a zero velocity.
fn relative(eta: f64, norm: f64) -> f64 {
    if eta == 0.0 {
        0.0
    } else {
        eta / norm
    }
}

/// The estimate of a whole run: each part's (k Σ_n η_n²)^½ over the steps added, and the
/// velocity's relative to (k Σ_n |w_n|²_V)^½.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RunEstimate {
    squares: [f64; 8],
    w_v2: f64,
    damage: bool,
}

impl RunEstimate {
    /// Adds a step's parts, with its |w_n|_V and the step length k.
    pub fn add(&mut self, step: &Parts, w_v: f64, k: f64) {
        let sq = step.squares();
        (0..8).for_each(|i| self.squares[i] += k * sq[i]);
        self.w_v2 += k * w_v * w_v;
        self.damage |= step.damage.is_some();
    }

    /// The run's parts so far.
    pub fn parts(&self) -> Parts {
        Parts::from_squares(&self.squares, self.w_v2, self.damage)
    }
}

#[cfg(test)]
mod tests;
