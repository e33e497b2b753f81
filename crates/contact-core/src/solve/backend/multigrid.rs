//! The multigrid family: conjugate gradients preconditioned by a multigrid V-cycle, with
//! hierarchies built once per run from the mesh's levels ([`crate::fem::multilevel`]).
//! - K_II: with a Γ3, solved through the hierarchy of K on all free DOFs (the Γ3 DOFs held
//!   at zero by the truncated V-cycle; K_II never copied), which also serves a slipping step:
//!   semismooth Newton on all free DOFs ([`crate::solve::semismooth_newton`]), no Schur
//!   complement: the slip solver [`FullSpaceNewton`]. Without a Γ3, K_II's own hierarchy.
//! - H: CG on the masked H, applied from H's storage, preconditioned by the V-cycle B of the
//!   whole H restricted to the free nodes (diag(B_FF, I): a principal block of an SPD matrix
//!   is SPD), started from the H-projection onto the earlier solutions of the same masked
//!   system (as K_II's solves, [`crate::linalg::projection`]), or where there are none from
//!   the extrapolated ζ; one hierarchy whatever the active set.
//! - The smallness estimate: λ_min by Lanczos on T = W^{½} S⁻¹ W^{½} ([`min_eig_by_lanczos`]),
//!   S never formed.
//!
//! Every operator is assembled into its sparsity pattern: no element triplets are held.

use super::Backend;
use crate::fem::{assembly, multilevel, DofMap, Geometry};
use crate::linalg::cholesky::FactorError;
use crate::linalg::dense::tridiagonal_max_eig;
use crate::linalg::multigrid::{Hierarchy, Params, VCycle};
use crate::linalg::pcg::{self, PcgWork, Preconditioner};
use crate::linalg::projection::{self, SolutionSpace};
use crate::linalg::solver::{NotConverged, MAX_KRYLOV_ITERATIONS};
use crate::linalg::{par, Csr, LinearOperator, LinearPath, LinearSolver, Sparse};
use crate::mesh::Mesh;
use crate::problem::FrictionLaw;
use crate::solve::damage::{Bound, DamageStep, MaskedSolver};
use crate::solve::galerkin_guess;
use crate::solve::semismooth_newton::SemismoothNewton;
use crate::solve::velocity::{ContactSolver, NoContact, SlipSolver, StepState, VelocityStep};
use crate::solve::{SolveError, SolverSettings};
use std::any::Any;
use std::sync::Arc;

/// The multigrid family.
pub struct Multigrid {
    predicted_bytes: u64,
    /// Single-precision level operators in every V-cycle ([`Params::mixed`]).
    mixed: bool,
}

impl Multigrid {
    pub fn new(predicted_bytes: u64, mixed: bool) -> Multigrid {
        Multigrid {
            predicted_bytes,
            mixed,
        }
    }

    fn params(&self) -> Params {
        Params {
            mixed: self.mixed,
            ..Params::default()
        }
    }
}

impl<const D: usize> Backend<D> for Multigrid {
    fn path(&self) -> LinearPath {
        LinearPath::Multigrid
    }

    fn predicted_bytes(&self) -> u64 {
        self.predicted_bytes
    }

    fn stiffness(
        &self,
        mesh: &Mesh<D>,
        geo: &Geometry<D>,
        dofs: &DofMap<D>,
        eta: f64,
        xi: f64,
    ) -> Csr {
        assembly::viscous_stiffness_in_pattern(mesh, geo, dofs, eta, xi)
    }

    fn mass(&self, mesh: &Mesh<D>, geo: &Geometry<D>) -> Csr {
        assembly::mass_in_pattern(mesh, geo)
    }

    fn laplacian(&self, mesh: &Mesh<D>, geo: &Geometry<D>, mass: &Csr) -> Csr {
        assembly::laplacian_in_pattern_of(mesh, geo, mass)
    }

    fn velocity(
        &self,
        k: Arc<Csr>,
        mesh: &Mesh<D>,
        dofs: &DofMap<D>,
        law: FrictionLaw,
    ) -> Result<VelocityStep, SolveError> {
        let factor_error = |source| SolveError::Factor {
            what: "velocity",
            source,
        };
        let n_i = dofs.n_interior;
        // One hierarchy, of K on all free DOFs: without a Γ3 K is K_II; with one, K_II is
        // solved through it too (the truncated cycle), and so are the slipping steps.
        let (blocks, levels) = multilevel::velocity_levels(mesh, dofs, dofs.n_free());
        let bounds = blocks.consecutive_bounds(k.nrows);
        let mut h =
            Hierarchy::new(k.clone(), blocks, levels, self.params()).map_err(factor_error)?;
        // After set-up K is only multiplied and read on Γ3 rows: with mixed precision, where
        // the V-cycle reads its f32 copy, the step holds it in f64 node blocks and the
        // hierarchy sheds its scalar copy, and A₁'s (the truncated cycles widen its f32 copy).
        let k = if self.mixed {
            let blocked = Sparse::in_blocks(&k, &bounds);
            h.shed_operators(&[]);
            // The scalar K goes before the truncated cycle is made, not at the end of
            // set-up: held beside its blocks it was the set-up's peak (123 of 470 MB on the
            // 82k-node part).
            drop(k);
            blocked
        } else {
            Sparse::from(k)
        };
        let h = Arc::new(h);
        if dofs.n_contact() == 0 {
            let k_ii = LinearSolver::with_hierarchy(h, k.clone());
            return Ok(
                VelocityStep::with_solver(k, dofs, law, k_ii, Box::new(NoContact))
                    .with_solution_space(),
            );
        }
        let k_ii = LinearSolver::leading_block(h.clone(), k.clone(), n_i).map_err(factor_error)?;
        let node_weights = dofs.contact.iter().step_by(D - 1).map(|c| c.weight);
        let newton = SemismoothNewton::new(
            k.clone(),
            h,
            n_i,
            D - 1,
            node_weights.collect(),
            law.clone(),
        );
        let slip = Box::new(FullSpaceNewton(newton));
        Ok(VelocityStep::with_solver(k, dofs, law, k_ii, slip).with_solution_space())
    }

    fn damage(&self, mesh: &Mesh<D>, h: Csr) -> Result<DamageStep, SolveError> {
        let (blocks, levels) = multilevel::scalar_levels(mesh, h.nrows);
        let h = Arc::new(h);
        let mut hierarchy =
            Hierarchy::new(h.clone(), blocks, levels, self.params()).map_err(|source| {
                SolveError::Factor {
                    what: "damage",
                    source,
                }
            })?;
        hierarchy.shed_operators(&[0]);
        let hierarchy = Arc::new(hierarchy);
        let n = h.nrows;
        let masked = MaskedCg::new(hierarchy.vcycle(), n);
        Ok(DamageStep::new(h, Box::new(masked)))
    }

    fn trace_eigenvalues(
        &self,
        mesh: &Mesh<D>,
        dofs: &DofMap<D>,
        gram: Csr,
        velocity: &mut VelocityStep,
    ) -> Result<(f64, f64), SolveError> {
        let w_sqrt: Vec<f64> = velocity.weights().iter().map(|w| w.sqrt()).collect();
        let (_, n_i) = velocity.operator();
        let k_hierarchy = velocity
            .linear_solver()
            .hierarchy()
            .expect("the multigrid path's")
            .clone();
        let mut k_solver = LinearSolver::with_hierarchy(k_hierarchy, velocity.shared_operator());
        let gram = Arc::new(gram);
        let (blocks, levels) = multilevel::velocity_levels(mesh, dofs, dofs.n_free());
        let g_hierarchy =
            Hierarchy::new(gram.clone(), blocks, levels, self.params()).map_err(|source| {
                SolveError::Factor {
                    what: "strain Gram",
                    source,
                }
            })?;
        let mut g_solver = LinearSolver::with_hierarchy(Arc::new(g_hierarchy), gram.into());
        let lambda_g = min_eig_by_lanczos(&mut g_solver, n_i, &w_sqrt)?;
        let lambda_a = min_eig_by_lanczos(&mut k_solver, n_i, &w_sqrt)?;
        Ok((lambda_g, lambda_a))
    }
}

/// The Newton iterations of a slipping step solve their Jacobian systems (at least) to this
/// fraction of the step's tolerance: the full KKT residual then stays a decade below the
/// tolerance, and the norms agree with the direct path to about 1e-13 (box-exp3 at 1/16: 2e-14
/// with g = 2, where 0.01 cost 25 % more iterations).
const JACOBIAN_FRACTION: f64 = 0.1;

/// A slipping step on all free DOFs: semismooth Newton with the hierarchy of K, started from
/// the minimiser of E over the span of the earlier velocities ([`galerkin_guess`]; no worse
/// in energy than the last step's velocity, or after an all-stick step this step's stick
/// solution); S never formed. A step after a slipping one comes here at once.
#[derive(Clone)]
pub struct FullSpaceNewton(SemismoothNewton);

impl SlipSolver for FullSpaceNewton {
    fn report(&self) -> ContactSolver {
        ContactSolver::SemismoothNewton
    }

    fn after_slip_at_once(&self) -> bool {
        true
    }

    fn solve(
        &mut self,
        state: &mut StepState,
        f: &[f64],
        w: &mut [f64],
        settings: &SolverSettings,
        step: usize,
    ) -> Result<usize, SolveError> {
        let n_i = state.n_i;
        w.copy_from_slice(&state.w_last);
        if state.x.iter().all(|&v| v == 0.0) {
            w[..n_i].copy_from_slice(&state.y);
        }
        if let Some(space) = &mut state.space {
            let contact = galerkin_guess::Contact {
                n_interior: n_i,
                block: state.block,
                weights: &state.node_weights,
                law: &state.law,
            };
            galerkin_guess::minimise(space, f, &contact, w);
        }
        // Half the tolerance, as the dense reduced solve: the full check follows.
        let inner = SolverSettings {
            tolerance: 0.5 * settings.tolerance,
            ..*settings
        };
        let newton = &mut self.0;
        let rep = newton.solve(f, w, &inner, JACOBIAN_FRACTION * settings.tolerance, step)?;
        state.krylov += rep.krylov_iterations;
        state.r.copy_from_slice(newton.gradient());
        state.r_fresh = true;
        state.x.copy_from_slice(&w[n_i..]);
        if let Some(space) = &mut state.space {
            space.extend(&state.k, w);
            state.space_slips |= state.x.iter().any(|&v| v != 0.0);
        }
        Ok(rep.newton_iterations)
    }

    fn boxed_clone(&self) -> Box<dyn SlipSolver> {
        Box::new(self.clone())
    }

    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}

/// H with the rows and columns of the active nodes replaced by the identity, applied from
/// H's storage (the masked matrix is never formed).
struct Masked<'a> {
    h: &'a Csr,
    active: &'a [Bound],
}

impl LinearOperator for Masked<'_> {
    fn dim(&self) -> usize {
        self.h.nrows
    }

    fn apply(&self, x: &[f64], y: &mut [f64]) {
        let h = self.h;
        par::for_each_chunk_mut(y, par::ROW_CHUNK, |first, y| {
            for (i, yr) in y.iter_mut().enumerate() {
                let r = first + i;
                *yr = if self.active[r] != Bound::Free {
                    x[r]
                } else {
                    // The active columns are multiplied by zero, not skipped: a branch on
                    // each column mispredicts where free and active nodes mix. Four partial
                    // sums keep the additions from waiting on one another.
                    let row = h.indptr[r]..h.indptr[r + 1];
                    let term = |c: u32, v: f64| {
                        let free = (self.active[c as usize] == Bound::Free) as u8 as f64;
                        v * free * x[c as usize]
                    };
                    let (c4, v4) = (
                        h.indices[row.clone()].chunks_exact(4),
                        h.values[row].chunks_exact(4),
                    );
                    let (c_rest, v_rest) = (c4.remainder(), v4.remainder());
                    let mut sum = [0.0f64; 4];
                    for (c, v) in c4.zip(v4) {
                        for k in 0..4 {
                            sum[k] += term(c[k], v[k]);
                        }
                    }
                    for (k, (&c, &v)) in c_rest.iter().zip(v_rest).enumerate() {
                        sum[k] += term(c, v);
                    }
                    (sum[0] + sum[1]) + (sum[2] + sum[3])
                };
            }
        });
    }
}

/// diag(B_FF, I) for the V-cycle B of H and the free set F.
struct MaskedVCycle<'a> {
    vcycle: &'a mut VCycle,
    active: &'a [Bound],
    buffer: &'a mut Vec<f64>,
}

impl Preconditioner for MaskedVCycle<'_> {
    fn apply(&mut self, r: &[f64], z: &mut [f64]) {
        for ((b, &r), a) in self.buffer.iter_mut().zip(r).zip(self.active) {
            *b = if *a == Bound::Free { r } else { 0.0 };
        }
        self.vcycle.apply(self.buffer, z);
        for ((z, &r), a) in z.iter_mut().zip(r).zip(self.active) {
            if *a != Bound::Free {
                *z = r;
            }
        }
    }
}

/// CG on the masked H with the masked V-cycle of H's hierarchy, started from the
/// H-orthogonal projection of the solution onto the span of the earlier solutions of the same
/// masked system ([`SolutionSpace`]).
struct MaskedCg {
    vcycle: VCycle,
    work: PcgWork,
    buffer: Vec<f64>,
    /// The earlier solutions of the masked system of `space_active`: H is fixed for the run,
    /// so while the active set stays (in most steps, every PDAS iteration of them) the
    /// systems differ only in their right-hand sides.
    space: SolutionSpace,
    space_active: Vec<Bound>,
}

impl MaskedCg {
    fn new(vcycle: VCycle, n: usize) -> MaskedCg {
        MaskedCg {
            vcycle,
            work: PcgWork::new(n),
            buffer: vec![0.0; n],
            space: SolutionSpace::new(n, projection::CAPACITY),
            space_active: vec![Bound::Free; n],
        }
    }
}

impl MaskedSolver for MaskedCg {
    fn set_active(&mut self, _h: &Csr, _active: &[Bound]) -> Result<(), FactorError> {
        Ok(())
    }

    fn solve(
        &mut self,
        h: &Csr,
        active: &[Bound],
        rhs: &[f64],
        zeta: &mut [f64],
        atol: f64,
    ) -> Result<usize, NotConverged> {
        let masked = Masked { h, active };
        if self.space_active != active {
            self.space.clear();
            self.space_active.copy_from_slice(active);
        }
        // The projection is the best start in the span in H's energy norm; an empty span
        // keeps the caller's start (the extrapolation in time).
        if !self.space.is_empty() {
            self.space.project(rhs, zeta);
        }
        for ((z, a), r) in zeta.iter_mut().zip(active).zip(rhs) {
            if *a != Bound::Free {
                *z = *r;
            }
        }
        let mut pre = MaskedVCycle {
            vcycle: &mut self.vcycle,
            active,
            buffer: &mut self.buffer,
        };
        let rep = pcg::solve(
            &masked,
            &mut pre,
            rhs,
            zeta,
            atol,
            MAX_KRYLOV_ITERATIONS,
            &mut self.work,
        );
        if rep.converged {
            self.space.extend(&masked, zeta);
            Ok(rep.iterations)
        } else {
            Err(NotConverged {
                iterations: rep.iterations,
                residual: rep.residual,
            })
        }
    }

    /// Iterative solves leave ζ accurate to about the damage step's Krylov fraction of the
    /// tolerance: the hysteresis must exceed that or degenerate nodes flip back and forth.
    fn hysteresis(&self, tolerance: f64) -> f64 {
        0.1 * tolerance
    }

    fn factorizations(&self) -> usize {
        0
    }
}

/// Most Lanczos steps.
const LANCZOS_STEPS: usize = 300;
/// Each solve of the Lanczos iteration stops at this max-norm residual relative to its load.
const SOLVE_TOLERANCE: f64 = 1e-11;
/// Lanczos stops when the largest Ritz value moves by less than this, relative.
const LANCZOS_TOLERANCE: f64 = 1e-10;

/// λ_min(W^{-½} S W^{-½}) for S the Schur complement of the solver's operator A (n × n) onto
/// its DOFs from `lead` on, W = diag(w_sqrt²): 1/λ_max of T = W^{½} (A⁻¹)_CC W^{½} by Lanczos
/// with full reorthogonalisation from a fixed start vector (deterministic); each product with
/// T is one solve A z = [0; W^{½} v] to [`SOLVE_TOLERANCE`].
pub fn min_eig_by_lanczos(
    a: &mut LinearSolver,
    lead: usize,
    w_sqrt: &[f64],
) -> Result<f64, SolveError> {
    let n = a.n();
    let m = n - lead;
    if m == 0 {
        return Ok(f64::INFINITY);
    }
    let mut apply = |v: &[f64], out: &mut [f64], z: &mut Vec<f64>| -> Result<(), SolveError> {
        let mut b = vec![0.0; n];
        for i in 0..m {
            b[lead + i] = w_sqrt[i] * v[i];
        }
        let scale = b.iter().fold(f64::MIN_POSITIVE, |s, x| s.max(x.abs()));
        z.iter_mut().for_each(|x| *x = 0.0);
        a.solve(&b, z, SOLVE_TOLERANCE * scale)
            .map_err(|e| SolveError::NotConverged {
                what: "smallness check (multigrid solve of the Lanczos iteration)",
                step: 0,
                iterations: e.iterations,
                residual: e.residual / scale,
                tolerance: SOLVE_TOLERANCE,
            })?;
        for i in 0..m {
            out[i] = w_sqrt[i] * z[lead + i];
        }
        Ok(())
    };
    let mut z = vec![0.0; n];
    let mut basis: Vec<Vec<f64>> = Vec::new();
    let mut v: Vec<f64> = (0..m)
        .map(|i| 1.0 + 0.5 * ((i as f64) * 0.618_033_988_7).fract())
        .collect();
    let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    let s = norm(&v);
    v.iter_mut().for_each(|x| *x /= s);
    let (mut alphas, mut betas) = (Vec::new(), Vec::new());
    let mut w = vec![0.0; m];
    let mut last = 0.0;
    for step in 0..LANCZOS_STEPS.min(m) {
        apply(&v, &mut w, &mut z)?;
        let alpha: f64 = w.iter().zip(&v).map(|(a, b)| a * b).sum();
        basis.push(v.clone());
        // Full reorthogonalisation (twice) against every basis vector.
        for _ in 0..2 {
            for q in &basis {
                let c: f64 = w.iter().zip(q).map(|(a, b)| a * b).sum();
                w.iter_mut().zip(q).for_each(|(a, b)| *a -= c * b);
            }
        }
        alphas.push(alpha);
        let beta = norm(&w);
        let top = tridiagonal_max_eig(&alphas, &betas);
        if step > 0 && (top - last).abs() <= LANCZOS_TOLERANCE * top || beta <= 1e-14 * top {
            return Ok(1.0 / top);
        }
        last = top;
        betas.push(beta);
        v.iter_mut().zip(&w).for_each(|(v, w)| *v = w / beta);
    }
    Ok(1.0 / last)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{self, presets};
    use serde_json::json;

    /// K is held once on the multigrid path, with or without a Γ3: with mixed precision in
    /// f64 node blocks and no scalar copy left in the hierarchy; in double precision as the
    /// one scalar K that the hierarchy smooths with. (A contact-free run once held K twice:
    /// as the step's K and as a K_II copy for CG.)
    #[test]
    fn k_is_held_once_with_and_without_a_contact_boundary() {
        for contact in [true, false] {
            let mut doc = presets::get("box-exp3").unwrap();
            doc["mesh"]["h"] = json!("1/16");
            if !contact {
                let boundary = doc["boundary"].as_array_mut().unwrap();
                boundary.retain(|b| b["type"] != "contact");
            }
            let p = scene::validate(&doc).unwrap();
            let mesh = p.mesh::<3>().unwrap();
            let geo = Geometry::new(&mesh);
            let dofs = DofMap::new(&mesh, &p.boundary);
            assert_eq!(dofs.n_contact() > 0, contact);
            let visc = p.material.viscosity;
            for mixed in [false, true] {
                let backend = Multigrid::new(0, mixed);
                let k = Backend::<3>::stiffness(&backend, &mesh, &geo, &dofs, visc.eta, visc.xi);
                let step = backend
                    .velocity(Arc::new(k), &mesh, &dofs, p.friction.clone())
                    .unwrap();
                let h = step.linear_solver().hierarchy().unwrap();
                assert!(h.n_levels() > 1, "{:?}", h.sizes());
                match step.operator().0 {
                    Sparse::Blocks(_) => {
                        assert!(mixed, "contact {contact}");
                        assert!(h.operator_at(0).is_none(), "contact {contact}");
                    }
                    Sparse::Scalar(k) => {
                        assert!(!mixed, "contact {contact}");
                        let finest = h.operator_at(0).unwrap();
                        assert!(std::ptr::eq(k.as_ref(), finest), "contact {contact}");
                    }
                }
            }
        }
    }

    /// The masked product from H's storage equals the product with the masked matrix formed
    /// entry by entry: rows of every length around the four partial sums, free and active
    /// nodes mixed.
    #[test]
    fn the_masked_product_is_that_of_h_with_active_rows_and_columns_made_identity() {
        let n: usize = 40;
        let mut t = Vec::new();
        for i in 0..n {
            for j in 0..n {
                let near = i.abs_diff(j) <= 1 + (i % 6);
                if near {
                    let v = if i == j {
                        20.0
                    } else {
                        -0.3 - 0.01 * (i + j) as f64
                    };
                    t.push((i, j, v));
                }
            }
        }
        let h = Csr::from_triplets(n, n, t);
        let active: Vec<Bound> = (0..n)
            .map(|i| match i % 5 {
                1 => Bound::Lower,
                3 => Bound::Upper,
                _ => Bound::Free,
            })
            .collect();
        let x: Vec<f64> = (0..n).map(|i| (0.7 * i as f64).sin() + 0.2).collect();
        let mut y = vec![f64::NAN; n];
        Masked {
            h: &h,
            active: &active,
        }
        .apply(&x, &mut y);
        let free = |i: usize| active[i] == Bound::Free;
        for i in 0..n {
            let expected = if free(i) {
                (0..n)
                    .filter(|&j| free(j))
                    .map(|j| h.get(i, j) * x[j])
                    .sum()
            } else {
                x[i]
            };
            assert!(
                (y[i] - expected).abs() <= 1e-13 * expected.abs().max(1.0),
                "row {i}: {} against {expected}",
                y[i]
            );
        }
    }
}
