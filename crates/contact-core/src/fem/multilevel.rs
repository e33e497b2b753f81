//! The linear solvers of a run's two SPD operators, set up from the mesh: which DOFs form a
//! node block, the near-nullspace, and — for a mesh made by red refinement of a given one —
//! the geometric prolongators of its nested levels.
//!
//! Geometric levels (a given or polygon mesh with `mesh.refine` ≥ 1): level l's nodes are the
//! first nodes of level l + 1 (red refinement keeps them and appends the edge midpoints), so
//! a coarse level's DOFs are the finest level's free DOFs at its nodes, in the same contact
//! frames. P maps them to the finer level: a kept node copies its DOF; a midpoint of edge
//! (a, b) takes ½ of each end's vector, written in its own frame:
//! P[(i, r), (e, s)] = ½ t_{i,r} · t_{e,s} (t the frame's unit vectors). Γ1 and the Γ3
//! normals are thus absent on every level, and A_{l+1} = Pᵀ A_l P keeps them.
//! Meshes without such levels (the mesh as given, generated rectangles and boxes) use
//! smoothed aggregation with the rigid-body modes.

#![allow(clippy::needless_range_loop)] // Index loops over nodes, blocks and components spell out the formulas.

use super::rigid_modes::{self, node_blocks, rigid_modes};
use super::{DofMap, Slot};
use crate::linalg::cholesky::FactorError;
use crate::linalg::multigrid::{Blocks, Coarsening};
use crate::linalg::{Csr, LinearPath, LinearSolver};
use crate::mesh::Mesh;
use std::sync::Arc;

/// The solver of the leading block (the first `lead` free DOFs: the interior ones) of a
/// velocity-type operator `a` on the path given (`Auto` is resolved by the caller).
pub fn velocity_solver<const D: usize>(
    mesh: &Mesh<D>,
    dofs: &DofMap<D>,
    a: Csr,
    lead: usize,
    path: LinearPath,
) -> Result<LinearSolver, FactorError> {
    if path != LinearPath::Multigrid {
        return LinearSolver::direct(&a);
    }
    let blocks = restrict(&node_blocks(mesh, dofs), lead);
    let coarsening = if mesh.nesting.is_empty() {
        let k = rigid_modes::count(D);
        let mut modes = rigid_modes(mesh, dofs);
        modes.truncate(lead * k);
        Coarsening::Aggregation {
            nullspace: modes,
            k,
        }
    } else {
        let (prolongators, blocks) = geometric(mesh, dofs, lead);
        Coarsening::Geometric {
            prolongators,
            blocks,
        }
    };
    LinearSolver::multigrid(Arc::new(a), blocks, coarsening)
}

/// The solver of a scalar nodal operator (the damage matrix H) on the path given.
pub fn scalar_solver(a: Csr, path: LinearPath) -> Result<LinearSolver, FactorError> {
    if path != LinearPath::Multigrid {
        return LinearSolver::direct(&a);
    }
    let n = a.nrows;
    LinearSolver::multigrid(
        Arc::new(a),
        Blocks::scalar(n),
        Coarsening::Aggregation {
            nullspace: vec![1.0; n],
            k: 1,
        },
    )
}

/// The blocks with only DOFs below `lead`.
fn restrict(blocks: &Blocks, lead: usize) -> Blocks {
    let mut of = vec![u32::MAX; lead];
    for b in 0..blocks.len() {
        for &i in blocks.dofs(b) {
            if i < lead {
                of[i] = b as u32;
            }
        }
    }
    Blocks::from_block_of(&of, blocks.len())
}

/// The prolongators of the refinement levels, finest first, and each coarser level's blocks.
fn geometric<const D: usize>(
    mesh: &Mesh<D>,
    dofs: &DofMap<D>,
    lead: usize,
) -> (Vec<Csr>, Vec<Blocks>) {
    // The finest free DOFs kept, as (node, local component), in free order.
    let mut kept = vec![(0usize, 0usize); lead];
    for (dof, s) in dofs.slot.iter().enumerate() {
        if let Slot::Free(f) = *s {
            if f < lead {
                kept[f] = (dof / D, dof % D);
            }
        }
    }
    let axis = |node: usize, r: usize| -> [f64; D] {
        match dofs.frame(node) {
            Some(rows) => rows[r],
            None => std::array::from_fn(|c| if c == r { 1.0 } else { 0.0 }),
        }
    };
    let mut prolongators = Vec::new();
    let mut coarse_blocks = Vec::new();
    let mut fine_nodes = mesh.n_nodes();
    for nest in mesh.nesting.iter().rev() {
        let nc = nest.coarse_nodes;
        // Level-local numbering of the kept DOFs on the fine and coarse levels.
        let fine: Vec<usize> = (0..lead).filter(|&f| kept[f].0 < fine_nodes).collect();
        let mut coarse_index = vec![usize::MAX; lead];
        let mut coarse_of_node: Vec<Vec<(usize, usize)>> = vec![Vec::new(); nc];
        let mut nc_dofs = 0;
        for &f in &fine {
            let (node, r) = kept[f];
            if node < nc {
                coarse_index[f] = nc_dofs;
                coarse_of_node[node].push((r, nc_dofs));
                nc_dofs += 1;
            }
        }
        let mut t = Vec::new();
        for (fi, &f) in fine.iter().enumerate() {
            let (node, r) = kept[f];
            if node < nc {
                t.push((fi, coarse_index[f], 1.0));
                continue;
            }
            let ti = axis(node, r);
            for &e in &nest.midpoints[node - nc] {
                for &(s, ci) in &coarse_of_node[e] {
                    let te = axis(e, s);
                    let v: f64 = (0..D).map(|c| ti[c] * te[c]).sum();
                    if v != 0.0 {
                        t.push((fi, ci, 0.5 * v));
                    }
                }
            }
        }
        prolongators.push(Csr::from_triplets(fine.len(), nc_dofs, t));
        let mut block_of = vec![0u32; nc_dofs];
        for (node, list) in coarse_of_node.iter().enumerate() {
            for &(_, ci) in list {
                block_of[ci] = node as u32;
            }
        }
        coarse_blocks.push(Blocks::from_block_of(&block_of, nc));
        fine_nodes = nc;
    }
    (prolongators, coarse_blocks)
}
