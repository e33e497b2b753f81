//! The solvers of Problem 3.1: the velocity hemivariational inequality (3.13) reduced to the
//! Γ3 tangential DOFs, the damage variational inequality (3.10) as a box-constrained QP, the
//! smallness condition (2.31), and the time step that couples them ([`stepper`];
//! [`crate::run`] loops over the steps).

pub mod backend;
pub mod damage;
pub mod friction_isotropic;
pub mod friction_node;
pub mod friction_reduced;
pub mod galerkin_guess;
pub mod invariants;
pub mod reduced;
pub mod semismooth_newton;
pub mod smallness;
pub mod stepper;
pub mod velocity;

/// Iterations and the relative optimality (KKT) residual a sub-problem solver reached.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SolverReport {
    pub iterations: usize,
    pub residual: f64,
    /// Conjugate-gradient iterations of the step's linear solves (multigrid path only; absent
    /// from the direct path's reports).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub krylov_iterations: usize,
}

fn is_zero(v: &usize) -> bool {
    *v == 0
}

/// Settings shared by the sub-problem solvers.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SolverSettings {
    /// Relative optimality residual to reach (default 1e-10).
    pub tolerance: f64,
    /// Iteration limit of each sub-problem solver.
    pub max_iterations: usize,
    /// The node's per-job memory limit in bytes (None: no limit): the linear path is chosen
    /// so that the predicted peak fits ([`crate::memory::choose`]).
    #[serde(skip)]
    pub memory_limit: Option<u64>,
    /// Threads of the run ([`crate::linalg::par`]; at least 1): a setting of the machine,
    /// not of the computation, whose numbers are the same bits for any count.
    #[serde(skip)]
    pub threads: usize,
}

impl SolverSettings {
    /// True when a solver used at least 80 % of its iteration limit: the step converged, but
    /// a slightly harder one might not (reported per run as a warning sign).
    pub fn near_iteration_limit(&self, iterations: usize) -> bool {
        iterations * 5 >= self.max_iterations * 4
    }
}

impl Default for SolverSettings {
    fn default() -> Self {
        SolverSettings {
            tolerance: 1e-10,
            max_iterations: 500,
            memory_limit: None,
            threads: 1,
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum SolveError {
    #[error("{what} did not converge at step {step}: {iterations} iterations, residual {residual:.3e} > tolerance {tolerance:.1e}")]
    NotConverged {
        what: &'static str,
        step: usize,
        iterations: usize,
        residual: f64,
        tolerance: f64,
    },
    #[error("factorisation of the {what} matrix failed: {source}")]
    Factor {
        what: &'static str,
        #[source]
        source: crate::linalg::cholesky::FactorError,
    },
    #[error("the smallness condition (2.31) fails for this scene: {0}")]
    Smallness(String),
    #[error("non-finite value in the {0} at step {1}")]
    NonFinite(&'static str, usize),
    /// Scene data that validation's sampling let through but that is unusable where the
    /// scheme evaluates it (a formula that is infinite or NaN at a quadrature point or time
    /// node, an initial damage outside [0, 1] at a node). `pointer` is the field's RFC 6901
    /// JSON pointer in the scene.
    #[error("invalid scene data at {pointer}: {message}")]
    Data { pointer: String, message: String },
    /// The run does not fit the per-job memory limit on any allowed path (found before any
    /// numeric work).
    #[error("{0}")]
    Memory(#[from] crate::memory::MemoryError),
}
