//! The solver backend of a run: how its linear systems and its slipping velocity steps are
//! solved, chosen once per run by [`choose`] from the problem (`solver.linear`, the mesh's
//! counts) and the per-job memory limit, before any operator is assembled. A backend family
//! assembles the run's operators and builds on them every solver the scheme needs:
//! - the velocity step (3.13): the solver of K_II, the interior block of the velocity
//!   operator, and its solver of slipping steps
//!   ([`SlipSolver`](super::velocity::SlipSolver));
//! - the damage step (3.10): the solver of H = M/k + κL masked by the active set
//!   ([`MaskedSolver`](super::damage::MaskedSolver));
//! - the smallness estimate (2.31): λ_min of the Schur complements onto Γ3.
//!
//! Families, one per file, with nothing in common but [`Backend`]:
//! - [`direct`]: sparse Cholesky factors of K_II and H, the dense reduced problem on Γ3;
//! - [`multigrid`]: conjugate gradients preconditioned by a multigrid V-cycle, semismooth
//!   Newton on all free DOFs for a slipping step.
//!
//! The choice reads the prediction of [`crate::memory`]: `auto` and a demanded path are
//! picked on the count model; a direct pick is then confirmed on the exact sizes of its
//! factors, from symbolic analyses of the operators' patterns (nothing assembled yet), and
//! moves to the multigrid path when only that fits.

pub mod direct;
pub mod multigrid;

use super::damage::DamageStep;
use super::velocity::VelocityStep;
use super::SolveError;
use crate::fem::{DofMap, Geometry};
use crate::linalg::{Csr, LinearPath};
use crate::memory;
use crate::mesh::Mesh;
use crate::problem::{FrictionLaw, Problem};
use std::sync::Arc;

/// A family of solvers for a D-dimensional run: what the set-up asks of it.
pub trait Backend<const D: usize>: Send + Sync {
    /// The linear path it is.
    fn path(&self) -> LinearPath;

    /// The run's predicted peak bytes on it.
    fn predicted_bytes(&self) -> u64;

    /// (A ε(·), ε(·)) with A(τ) = 2η τ + ξ tr(τ) I on the free DOFs, interior first: the
    /// velocity operator K of (3.13), or with η = ½, ξ = 0 the Gram matrix of ‖ε(·)‖.
    fn stiffness(
        &self,
        mesh: &Mesh<D>,
        geo: &Geometry<D>,
        dofs: &DofMap<D>,
        eta: f64,
        xi: f64,
    ) -> Csr;

    /// The P1 mass matrix M.
    fn mass(&self, mesh: &Mesh<D>, geo: &Geometry<D>) -> Csr;

    /// The P1 Laplacian L, with the pattern of `mass` (H = M/k + κL adds them entrywise).
    fn laplacian(&self, mesh: &Mesh<D>, geo: &Geometry<D>, mass: &Csr) -> Csr;

    /// The velocity step (3.13) on K (all free DOFs, interior first) with this family's
    /// solver of K_II and of a slipping step.
    fn velocity(
        &self,
        k: Arc<Csr>,
        mesh: &Mesh<D>,
        dofs: &DofMap<D>,
        law: FrictionLaw,
    ) -> Result<VelocityStep, SolveError>;

    /// The damage step (3.10) on H = M/k + κL.
    fn damage(&self, mesh: &Mesh<D>, h: Csr) -> Result<DamageStep, SolveError>;

    /// (λ_G, λ_A) = λ_min(W^{-½} S W^{-½}) for S the Schur complements onto the Γ3
    /// tangential DOFs of the Gram matrix `gram` and of the velocity step's K, W = diag(ω)
    /// per contact DOF (the smallness estimate, [`super::smallness`]).
    fn trace_eigenvalues(
        &self,
        mesh: &Mesh<D>,
        dofs: &DofMap<D>,
        gram: Csr,
        velocity: &mut VelocityStep,
    ) -> Result<(f64, f64), SolveError>;
}

/// The path the count model picks for `problem` under `memory_limit` (None: no limit) and
/// its predicted bytes, before any mesh exists; or the refusal when no allowed path fits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pick {
    pub path: LinearPath,
    pub predicted_bytes: u64,
}

/// The first half of [`choose`]: the count model's pick ([`memory::predict`]; a demanded
/// direct path only against what is certain before its analyses,
/// [`memory::without_factors`]).
pub fn pick(problem: &Problem, memory_limit: Option<u64>) -> Result<Pick, memory::MemoryError> {
    let first = match problem.linear {
        LinearPath::Direct => memory::without_factors(problem),
        _ => memory::predict(problem),
    };
    let (path, predicted_bytes) = memory::choose_with(problem, memory_limit, first)?;
    Ok(Pick {
        path,
        predicted_bytes,
    })
}

/// The second half of [`choose`]: the backend of `pick` on the run's mesh, a direct pick
/// confirmed on the exact sizes of its factors (symbolic analyses of the patterns, nothing
/// assembled) and moved to the multigrid path when only that fits.
pub fn confirm<const D: usize>(
    pick: Pick,
    problem: &Problem,
    mesh: &Mesh<D>,
    dofs: &DofMap<D>,
    memory_limit: Option<u64>,
) -> Result<Arc<dyn Backend<D>>, SolveError> {
    let Pick {
        mut path,
        predicted_bytes: mut bytes,
    } = pick;
    let mut plans = None;
    if path == LinearPath::Direct {
        let analysed = direct::Plans::analyse(problem, mesh, dofs)?;
        let exact = memory::refine(problem, &analysed.all());
        (path, bytes) = memory::choose_with(problem, memory_limit, exact)?;
        plans = Some(analysed);
    }
    // One line per family.
    Ok(match (path, plans) {
        (LinearPath::Direct, Some(plans)) => Arc::new(direct::Direct::new(plans, bytes)),
        _ => Arc::new(multigrid::Multigrid::new(bytes, problem.precision.mixed(D))),
    })
}

/// The backend of a run of `problem` on `mesh` under `memory_limit` (None: no limit), or
/// the refusal when no allowed path fits ([`memory::MemoryError`]).
pub fn choose<const D: usize>(
    problem: &Problem,
    mesh: &Mesh<D>,
    dofs: &DofMap<D>,
    memory_limit: Option<u64>,
) -> Result<Arc<dyn Backend<D>>, SolveError> {
    let pick = pick(problem, memory_limit)?;
    confirm(pick, problem, mesh, dofs, memory_limit)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::memory::MemoryError;
    use crate::scene::{self, presets};
    use serde_json::json;

    fn problem(preset: &str, h: &str, linear: &str) -> Problem {
        let mut doc = presets::get(preset).unwrap();
        doc["mesh"]["h"] = json!(h);
        doc["time"] = json!({"T": 1, "N": 1});
        doc["solver"] = json!({"linear": linear});
        scene::validate(&doc).unwrap()
    }

    fn backend<const D: usize>(
        p: &Problem,
        limit: Option<u64>,
    ) -> Result<Arc<dyn Backend<D>>, SolveError> {
        let mesh = p.mesh::<D>().unwrap();
        let dofs = DofMap::new(&mesh, &p.boundary);
        choose(p, &mesh, &dofs, limit)
    }

    /// `auto` without a limit: the direct path in 2D and for small 3D bodies, multigrid for
    /// large 3D ones (the count model's pick, before any mesh).
    #[test]
    fn auto_picks_direct_in_2d_and_multigrid_for_large_3d() {
        let plane = problem("paper-exp3", "1/16", "auto");
        assert_eq!(
            backend::<2>(&plane, None).unwrap().path(),
            LinearPath::Direct
        );
        let small = problem("box-exp3", "1/4", "auto");
        assert_eq!(
            backend::<3>(&small, None).unwrap().path(),
            LinearPath::Direct
        );
        let large = problem("box-exp3", "1/24", "auto");
        let p = pick(&large, None).unwrap();
        assert_eq!(p.path, LinearPath::Multigrid);
        assert_eq!(p.predicted_bytes, memory::predict(&large).multigrid);
    }

    /// Under a limit that only the other path fits, `auto` takes it; the backend built says
    /// so and carries that path's prediction.
    #[test]
    fn auto_falls_back_to_the_path_that_fits() {
        let p = problem("paper-convergence", "1/64", "auto");
        let pred = memory::predict(&p);
        assert!(pred.multigrid < pred.direct, "{pred:?}");
        let b = backend::<2>(&p, Some(pred.multigrid)).unwrap();
        assert_eq!(
            (b.path(), b.predicted_bytes()),
            (LinearPath::Multigrid, pred.multigrid)
        );
        // With room for the direct path's exact figure, the direct path.
        let b = backend::<2>(&p, Some(pred.direct.max(pred.multigrid) * 4)).unwrap();
        assert_eq!(b.path(), LinearPath::Direct);
    }

    /// Nothing fits: refused before any mesh, with the field to blame.
    #[test]
    fn refusals_name_the_field_that_does_not_fit() {
        let p = problem("paper-exp3", "1/16", "auto");
        match pick(&p, Some(1)) {
            Err(e @ MemoryError::TooLarge { .. }) => assert_eq!(e.pointer(), "/mesh"),
            other => panic!("{other:?}"),
        }
        let direct = problem("paper-exp3", "1/16", "direct");
        let floor = memory::without_factors(&direct).direct;
        match backend::<2>(&direct, Some(floor - 1)) {
            Err(SolveError::Memory(e @ MemoryError::DirectTooLarge { .. })) => {
                assert_eq!(e.pointer(), "/solver/linear")
            }
            Err(e) => panic!("{e}"),
            Ok(b) => panic!("accepted on {:?}", b.path()),
        }
        let multigrid = problem("paper-exp3", "1/16", "multigrid");
        let needed = memory::predict(&multigrid).multigrid;
        match pick(&multigrid, Some(needed - 1)) {
            Err(e @ MemoryError::TooLarge { .. }) => assert_eq!(e.pointer(), "/mesh"),
            other => panic!("{other:?}"),
        }
        assert_eq!(
            pick(&multigrid, Some(needed)).unwrap().path,
            LinearPath::Multigrid
        );
    }

    /// A demanded direct path is confirmed on the exact sizes of its factors: the exact
    /// figure is the prediction of the backend built, and a limit just below it is refused.
    #[test]
    fn a_direct_pick_is_confirmed_on_its_exact_factors() {
        let p = problem("box-exp3", "1/4", "direct");
        let exact = backend::<3>(&p, None).unwrap().predicted_bytes();
        let mesh = p.mesh::<3>().unwrap();
        let dofs = DofMap::new(&mesh, &p.boundary);
        let plans = direct::Plans::analyse(&p, &mesh, &dofs).unwrap();
        assert_eq!(exact, memory::refine(&p, &plans.all()).direct);
        assert!(matches!(
            backend::<3>(&p, Some(exact - 1)),
            Err(SolveError::Memory(MemoryError::DirectTooLarge { .. }))
        ));
        assert_eq!(
            backend::<3>(&p, Some(exact)).unwrap().path(),
            LinearPath::Direct
        );
    }
}
