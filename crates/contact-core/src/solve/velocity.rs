//! The velocity step (3.13): w_n minimises
//!   E(w) = ½ (A ε(w), ε(w)) + (B_{n−1}, ε(w)) − (f_n, w) + Σ_i ω_i j(w_τ(x_i))
//! over the free DOFs. With K the matrix of (A ε(·), ε(·)) and f the load (external minus
//! the explicit elastic term), split interior (I) / contact-tangential (C) DOFs:
//!   [K_II K_IC; K_CI K_CC] [w_I; x] = [f_I; f_C − ∂J(x)].
//! Eliminating w_I = K_II⁻¹ (f_I − K_IC x) leaves the small non-smooth problem of
//! [`super::friction_reduced`] with S = K_CC − K_CI K_II⁻¹ K_IC and b = f_C − K_CI K_II⁻¹ f_I.
//!
//! K_II is factored once per job. Per step: one solve for y = K_II⁻¹ f_I; if every contact
//! node sticks (|b_i| ≤ ω_i μ(0), checked exactly) then x = 0 and w_I = y: done. Otherwise
//! S is formed (once, lazily, as the trailing block of a factor of K with the contact DOFs
//! last: [`crate::linalg::schur`]), the reduced problem is solved, and one more solve
//! recovers w_I.
//!
//! Each Γ3 node has d − 1 consecutive tangential DOFs: one in 2D (the reduced problem of
//! [`super::friction_reduced`]), two in 3D (the isotropic, group-sparse one of
//! [`super::friction_isotropic`], with the Euclidean norm of the node's 2-vector).

use super::{friction_isotropic, friction_reduced};
use super::{SolveError, SolverReport, SolverSettings};
use crate::fem::DofMap;
use crate::linalg::{schur_complement, Cholesky, Csr, SchurPath};
use crate::problem::FrictionLaw;
use nalgebra::DMatrix;

/// Most rounds of iterative refinement of the interior velocity per step.
const REFINEMENTS: usize = 3;

/// Cloning shares the factor of K_II (see [`Cholesky`]); the clone has its own warm start.
#[derive(Clone)]
pub struct VelocityStep {
    /// The operator on all free DOFs (for residuals), interior first, contact last.
    k: Csr,
    n_i: usize,
    k_ii: Cholesky,
    /// Contact rows, interior columns.
    k_ci: Csr,
    /// Tangential DOFs per Γ3 node: d − 1.
    block: usize,
    /// ω_i per contact DOF (repeated over a node's DOFs) ...
    weights: Vec<f64>,
    /// ... and per Γ3 node (what the 3D reduced problem takes).
    node_weights: Vec<f64>,
    law: FrictionLaw,
    /// How S is formed; after forming it, the path taken.
    schur_path: SchurPath,
    schur: Option<DMatrix<f64>>,
    /// Tangential velocities on Γ3 (the warm start of the next step).
    x: Vec<f64>,
    /// Reaction on the contact DOFs, −(S x − b): the discrete friction force at each node.
    reaction: Vec<f64>,
    y: Vec<f64>,
    r: Vec<f64>,
}

impl VelocityStep {
    /// Factors the free-DOF operator `k` (numbered as in `dofs`: interior, then contact).
    pub fn new<const D: usize>(
        k: Csr,
        dofs: &DofMap<D>,
        law: FrictionLaw,
        path: SchurPath,
    ) -> Result<Self, SolveError> {
        let n_i = dofs.n_interior;
        let n = dofs.n_free();
        let k_ii =
            Cholesky::new(k.block(0..n_i, 0..n_i).lower_csc().as_ref()).map_err(|source| {
                SolveError::Factor {
                    what: "velocity",
                    source,
                }
            })?;
        let k_ci = k.block(n_i..n, 0..n_i);
        let m = dofs.n_contact();
        Ok(VelocityStep {
            k,
            n_i,
            k_ii,
            k_ci,
            schur_path: path,
            block: D - 1,
            weights: dofs.contact.iter().map(|c| c.weight).collect(),
            node_weights: dofs
                .contact
                .iter()
                .step_by(D - 1)
                .map(|c| c.weight)
                .collect(),
            law,
            schur: None,
            x: vec![0.0; m],
            reaction: vec![0.0; m],
            y: vec![0.0; n_i],
            r: vec![0.0; n],
        })
    }

    pub fn n_contact(&self) -> usize {
        self.weights.len()
    }

    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// Tangential velocity of each Γ3 DOF after the last solve.
    pub fn contact_velocity(&self) -> &[f64] {
        &self.x
    }

    /// Discrete friction force −(S x − b) of each Γ3 DOF after the last solve (integrated over
    /// the node's share ω_i of Γ3; divide by ω_i for a traction density).
    pub fn contact_force(&self) -> &[f64] {
        &self.reaction
    }

    /// Set the warm start (e.g. when resuming from a checkpoint).
    pub fn set_contact_velocity(&mut self, x: &[f64]) {
        self.x.copy_from_slice(x);
    }

    /// Nonzeros of the factor of K_II and its dimension.
    pub fn factor_size(&self) -> (usize, usize) {
        (self.k_ii.n(), self.k_ii.nnz_l())
    }

    /// How S is (to be) formed.
    pub fn schur_path(&self) -> SchurPath {
        self.schur_path
    }

    /// The free-DOF operator K and the number of interior DOFs (for benchmarks).
    pub fn operator(&self) -> (&Csr, usize) {
        (&self.k, self.n_i)
    }

    /// One forward + backward substitution with the K_II factor, in place (for benchmarks).
    pub fn substitute(&mut self, v: &mut [f64]) {
        self.k_ii.solve_in_place(v);
    }

    /// S = K_CC − K_CI K_II⁻¹ K_IC, computed on first use.
    pub fn schur(&mut self) -> &DMatrix<f64> {
        if self.schur.is_none() {
            let (s, path) = schur_complement(&self.k, self.n_i, &self.k_ii, self.schur_path);
            self.schur = Some(s);
            self.schur_path = path;
        }
        self.schur.as_ref().unwrap()
    }

    /// Solves (3.13) for the free-DOF load `f`, writing the free-DOF velocity into `w`.
    /// The reported residual is the relative KKT residual of the FULL problem, computed from
    /// K w − f (not from the reduced quantities).
    pub fn solve(
        &mut self,
        f: &[f64],
        w: &mut [f64],
        settings: &SolverSettings,
        step: usize,
    ) -> Result<SolverReport, SolveError> {
        let n_i = self.n_i;
        let m = self.n_contact();
        self.y.copy_from_slice(&f[..n_i]);
        self.k_ii.solve_in_place(&mut self.y);
        let mut iterations = 0;
        if m > 0 {
            let mut b = f[n_i..].to_vec();
            let mut kci_y = vec![0.0; m];
            self.k_ci.mul_vec(&self.y, &mut kci_y);
            b.iter_mut().zip(&kci_y).for_each(|(b, v)| *b -= v);
            let mu0 = self.law.mu(0.0);
            let all_stick = match self.block {
                1 => b.iter().zip(&self.weights).all(|(b, w)| b.abs() <= w * mu0),
                _ => b
                    .chunks(self.block)
                    .zip(self.weights.chunks(self.block))
                    .all(|(b, w)| b.iter().map(|v| v * v).sum::<f64>().sqrt() <= w[0] * mu0),
            };
            if all_stick {
                self.x.iter_mut().for_each(|v| *v = 0.0);
                w[..n_i].copy_from_slice(&self.y);
            } else {
                let mut x = std::mem::take(&mut self.x);
                let law = self.law.clone();
                let weights = std::mem::take(&mut self.weights);
                let node_weights = std::mem::take(&mut self.node_weights);
                // Same force scale as the full residual below, and half its tolerance: the
                // recovery of the interior adds rounding only.
                let scale = f.iter().fold(f64::MIN_POSITIVE, |s, v| s.max(v.abs()));
                let inner = SolverSettings {
                    tolerance: 0.5 * settings.tolerance,
                    ..*settings
                };
                let block = self.block;
                let s = self.schur();
                let rep = match block {
                    1 => friction_reduced::solve(
                        &friction_reduced::Reduced {
                            s,
                            b: &b,
                            weights: &weights,
                            law: &law,
                            scale: Some(scale),
                        },
                        &mut x,
                        &inner,
                        step,
                    ),
                    _ => friction_isotropic::solve(
                        &friction_isotropic::Reduced {
                            s,
                            b: &b,
                            weights: &node_weights,
                            law: &law,
                            scale: Some(scale),
                        },
                        &mut x,
                        &inner,
                        step,
                    ),
                };
                self.weights = weights;
                self.node_weights = node_weights;
                iterations = rep?.iterations;
                // w_I = K_II⁻¹ (f_I − K_IC x).
                let wi = &mut w[..n_i];
                wi.copy_from_slice(&f[..n_i]);
                let mut kic_x = vec![0.0; n_i];
                self.k_ci.tmul_vec_add(&x, &mut kic_x);
                wi.iter_mut().zip(&kic_x).for_each(|(a, v)| *a -= v);
                self.k_ii.solve_in_place(wi);
                self.x = x;
            }
            w[n_i..].copy_from_slice(&self.x);
        } else {
            w.copy_from_slice(&self.y);
        }
        let scale = f.iter().fold(f64::MIN_POSITIVE, |s, v| s.max(v.abs()));
        let mut residual = self.full_residual(f, w) / scale;
        if residual > settings.tolerance && residual.is_finite() {
            residual = self.refine(f, w, scale, settings.tolerance);
        }
        if !residual.is_finite() {
            return Err(SolveError::NonFinite("velocity", step));
        }
        if residual > settings.tolerance {
            return Err(SolveError::NotConverged {
                what: "velocity step",
                step,
                iterations,
                residual,
                tolerance: settings.tolerance,
            });
        }
        Ok(SolverReport {
            iterations,
            residual,
        })
    }
}

impl VelocityStep {
    /// The fallback for ill-conditioned K (a slender body: its condition grows like
    /// (length/height)^4), where the rounding of K w alone, about ε·‖|K||w|‖∞, exceeds the
    /// tolerance times ‖f‖∞: a few rounds of iterative refinement of w_I (x fixed) with the
    /// same factor, then the residual relative to ‖|K||w|‖∞ instead of ‖f‖∞ (a normwise
    /// backward error: w solves K w = f + δ with ‖δ‖ ≤ residual·‖|K||w|‖∞). Steps that meet
    /// the tolerance relative to ‖f‖∞ never get here and stay bit for bit as they were.
    /// Returns the residual to report (relative to ‖f‖∞ if refinement reached the tolerance).
    fn refine(&mut self, f: &[f64], w: &mut [f64], scale: f64, tolerance: f64) -> f64 {
        let n_i = self.n_i;
        let mut residual = self.full_residual(f, w) / scale;
        for _ in 0..REFINEMENTS {
            let mut d = self.r[..n_i].to_vec();
            self.k_ii.solve_in_place(&mut d);
            let before = w[..n_i].to_vec();
            w[..n_i].iter_mut().zip(&d).for_each(|(w, d)| *w -= d);
            let refined = self.full_residual(f, w) / scale;
            if refined >= residual || refined.is_nan() {
                w[..n_i].copy_from_slice(&before);
                self.full_residual(f, w);
                break;
            }
            residual = refined;
            if residual <= tolerance {
                return residual;
            }
        }
        let k = &self.k;
        let floor = (0..k.nrows).fold(f64::MIN_POSITIVE, |m, i| {
            let row = k.indptr[i]..k.indptr[i + 1];
            let s: f64 = k.indices[row.clone()]
                .iter()
                .zip(&k.values[row])
                .map(|(&j, v)| (v * w[j]).abs())
                .sum();
            m.max(s)
        });
        residual * scale / floor.max(scale)
    }

    /// Full-system optimality of `w`: r = K w − f; interior rows must vanish, contact rows
    /// must satisfy the stick/slip conditions with g = r_C. Leaves r in `self.r` and the
    /// friction force −r_C in `self.reaction`; returns the larger violation (unscaled).
    fn full_residual(&mut self, f: &[f64], w: &[f64]) -> f64 {
        let n_i = self.n_i;
        self.k.mul_vec(w, &mut self.r);
        for (r, f) in self.r.iter_mut().zip(f) {
            *r -= f;
        }
        let interior = self.r[..n_i].iter().fold(0.0f64, |s, v| s.max(v.abs()));
        let contact = match self.block {
            1 => friction_reduced::kkt_violation(&self.r[n_i..], &self.x, &self.weights, &self.law),
            _ => friction_isotropic::kkt_violation(
                &self.r[n_i..],
                &self.x,
                &self.node_weights,
                &self.law,
            ),
        };
        for (q, r) in self.reaction.iter_mut().zip(&self.r[n_i..]) {
            *q = -r;
        }
        interior.max(contact)
    }
}
