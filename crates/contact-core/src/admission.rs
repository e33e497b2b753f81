//! Per-job limits of a host, checked before any numeric work for every run a job will make
//! (a simulation; every level, reference and pilot of a study): mesh nodes, time steps,
//! stored bytes of the requested output, and the peak memory on the linear path the run will
//! take ([`crate::memory::choose`]). A run that does not fit is refused at the member of the
//! request that makes it too large, with what it needs and what the host allows. The same
//! [`Limits`] bound the runs themselves: the set-up refuses a path whose exact figure does
//! not fit ([`crate::solve::stepper::Prepared::within`]).

use crate::linalg::LinearPath;
use crate::memory::{self, MemoryError};
use crate::problem::Problem;
use serde::Serialize;

/// A host's per-job limits (None: no limit).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Limits {
    pub max_nodes: Option<usize>,
    /// Time steps of the whole job (a study: of all its runs).
    pub max_steps: Option<usize>,
    pub max_stored_bytes: Option<u64>,
    /// Peak bytes of the job's process share ([`crate::memory`]).
    pub max_memory: Option<u64>,
}

/// Which limit a run goes over.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Limit {
    Nodes,
    Steps,
    StoredBytes,
    Memory,
}

/// A run that does not fit: where in the request, which limit, the figures and a sentence.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, thiserror::Error)]
#[error("{message}")]
pub struct LimitError {
    /// RFC 6901 pointer of the member that sets the size (`/study/reference/h`, `/mesh/h`).
    pub pointer: String,
    pub limit: Limit,
    /// What the run needs (nodes, steps or bytes; for memory the predicted peak) ...
    pub needed: u64,
    /// ... and what the host allows.
    pub allowed: u64,
    pub message: String,
}

/// The request members that set a run's sizes: the mesh (nodes and memory), the time step
/// (steps), the output selection (stored bytes), and the linear solver (a demanded direct
/// path that does not fit; None: blame the mesh, as a study does whose scene fixes the solver
/// for all its runs).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Pointers {
    pub mesh: String,
    pub steps: String,
    pub output: String,
    pub solver: Option<String>,
}

impl Pointers {
    /// The members of a scene document (`/mesh/h`, `/time/k`, `/output`, `/solver/linear`).
    pub fn scene() -> Pointers {
        Pointers {
            mesh: "/mesh/h".into(),
            steps: "/time/k".into(),
            output: "/output".into(),
            solver: Some("/solver/linear".into()),
        }
    }
}

/// What an admitted run will use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Fit {
    pub nodes: usize,
    /// Bytes its stored steps take ([`stored_bytes`]).
    pub stored_bytes: u64,
    /// The linear path it takes and that path's predicted peak.
    pub path: LinearPath,
    pub memory_bytes: u64,
}

/// Checks one run of `p` against every limit, in the order nodes, memory, steps, stored
/// bytes (the mesh first: it sets the others' scale).
pub fn check_run(p: &Problem, limits: &Limits, at: &Pointers) -> Result<Fit, LimitError> {
    let nodes = p.n_nodes();
    if let Some(max) = limits.max_nodes.filter(|&m| nodes > m) {
        return Err(LimitError {
            pointer: at.mesh.clone(),
            limit: Limit::Nodes,
            needed: nodes as u64,
            allowed: max as u64,
            message: format!("the mesh has {nodes} nodes, more than the per-job limit of {max}"),
        });
    }
    let (path, memory_bytes) = memory::choose(p, limits.max_memory).map_err(|e| {
        let (needed, allowed) = match e {
            MemoryError::DirectTooLarge {
                predicted, allowed, ..
            }
            | MemoryError::TooLarge {
                predicted, allowed, ..
            } => (predicted, allowed),
        };
        let pointer = match (&e, &at.solver) {
            (MemoryError::DirectTooLarge { .. }, Some(solver)) => solver.clone(),
            _ => at.mesh.clone(),
        };
        LimitError {
            pointer,
            limit: Limit::Memory,
            needed,
            allowed,
            message: e.to_string(),
        }
    })?;
    if let Some(max) = limits.max_steps.filter(|&m| p.steps > m) {
        return Err(LimitError {
            pointer: at.steps.clone(),
            limit: Limit::Steps,
            needed: p.steps as u64,
            allowed: max as u64,
            message: format!(
                "{} time steps, more than the per-job limit of {max}",
                p.steps
            ),
        });
    }
    let stored = stored_bytes(p);
    if let Some(max) = limits.max_stored_bytes.filter(|&m| stored > m) {
        return Err(LimitError {
            pointer: at.output.clone(),
            limit: Limit::StoredBytes,
            needed: stored,
            allowed: max,
            message: format!(
                "the selected output stores about {} MB, more than the per-job limit of {} MB; store fewer steps (output.every) or fields",
                stored >> 20,
                max >> 20
            ),
        });
    }
    Ok(Fit {
        nodes,
        stored_bytes: stored,
        path,
        memory_bytes,
    })
}

/// The bytes of the steps a run stores (the scene's `output`: its fields at its steps), an
/// upper estimate from counts: u and w are d values per node, ζ one, σ 3(d − 1) per cell
/// and its von Mises stress and a posteriori cell indicator one each; at most 4 triangles per rectangle cell (the cross pattern),
/// 6 tetrahedra per box cell, about 2 triangles per node on any triangulation and 6
/// tetrahedra per node on a tetrahedral mesh.
pub fn stored_bytes(p: &Problem) -> u64 {
    let nodes = p.n_nodes();
    let f = p.output.fields;
    let d = p.dim();
    let per_node = d * f.u as usize + d * f.w as usize + f.zeta as usize;
    let per_cell =
        3 * (d - 1) * f.sigma as usize + f.von_mises as usize + p.output.estimate as usize;
    let cells = match (&p.body, p.depth_cells()) {
        (None, Some(nz)) => {
            let (nx, ny) = p.cells();
            6 * nx * ny * nz
        }
        (None, None) => {
            let (nx, ny) = p.cells();
            4 * nx * ny
        }
        (Some(_), _) => 2 * (d - 1) * (d - 1) * nodes,
    };
    let values = (per_node as u64)
        .saturating_mul(nodes as u64)
        .saturating_add((per_cell as u64).saturating_mul(cells as u64));
    let per_step = values.saturating_mul(8).saturating_add(64);
    per_step.saturating_mul(p.output.stored_steps(p.steps) as u64)
}

#[cfg(test)]
mod tests;
