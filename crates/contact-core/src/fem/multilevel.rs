//! The levels of a run's two SPD operators for a multigrid hierarchy, from the mesh: which
//! DOFs form a node block, the near-nullspace, and — for a mesh with nested levels — the
//! geometric prolongators. The solvers built on them are the backend's
//! ([`crate::solve::backend`]).
//!
//! Geometric levels come from red refinement (a given or polygon mesh with `mesh.refine`
//! ≥ 1; the mesh as given is the coarsest level) or from halving a generated rectangle or
//! Kuhn box (the lattices of h and 2h are nested, [`super::prolongation`]). Either way each
//! coarse node is a node of the finer level, and a finer node's value is the P1 interpolant
//! of the coarse ones: a stencil of coarse nodes and barycentric weights w. A coarse level's
//! DOFs are the finest level's free DOFs at its nodes, in the same contact frames, and
//! P[(i, r), (e, s)] = w_{ie} t_{i,r} · t_{e,s} (t the frame's unit vectors), so Γ1 and the
//! Γ3 normals are absent on every level and A_{l+1} = Pᵀ A_l P keeps them.
//! Meshes without such levels (a mesh as given, odd cell counts) use smoothed aggregation
//! with the rigid-body modes.

#![allow(clippy::needless_range_loop)] // Index loops over nodes, blocks and components spell out the formulas.

use super::prolongation::{grid_stencils, lattice_stencils};
use super::rigid_modes::{self, node_blocks, rigid_modes, rigid_modes_at};
use super::{DofMap, Slot};
use crate::linalg::multigrid::{Below, Blocks, Coarsening};
use crate::linalg::Csr;
use crate::mesh::{Grid, Lattice, Mesh, MeshPattern};

/// A generated rectangle or box is halved while its finer level has more nodes than this;
/// the last level is factored directly (a few thousand DOFs).
const COARSE_NODES: usize = 700;

/// A coarsest geometric level with more DOFs than this (a large base mesh refined) is
/// aggregated further rather than factored: a 3D factor grows as n^1.6 (about 31 MB at this
/// size, 120 MB for an 8k-node part's 24k DOFs, held twice with a Γ3), and its substitutions
/// in every V-cycle outweighed the finest level's products there.
pub const FACTORED_DOFS: usize = 10_000;

/// The node blocks and the coarsening of a velocity-type operator on its first `lead` free
/// DOFs: geometric levels where the mesh has them, else smoothed aggregation with the
/// rigid-body modes.
pub fn velocity_levels<const D: usize>(
    mesh: &Mesh<D>,
    dofs: &DofMap<D>,
    lead: usize,
) -> (Blocks, Coarsening) {
    let blocks = restrict(&node_blocks(mesh, dofs), lead);
    let coarsening = geometric_velocity(mesh, dofs, lead).unwrap_or_else(|| {
        let k = rigid_modes::count(D);
        let mut modes = rigid_modes(mesh, dofs);
        modes.truncate(lead * k);
        Coarsening::Aggregation {
            nullspace: modes,
            k,
        }
    });
    (blocks, coarsening)
}

/// The geometric coarsening of a velocity-type operator on the first `lead` free DOFs, None
/// when the mesh has no nested levels.
pub fn geometric_velocity<const D: usize>(
    mesh: &Mesh<D>,
    dofs: &DofMap<D>,
    lead: usize,
) -> Option<Coarsening> {
    geometric_velocity_factoring(mesh, dofs, lead, FACTORED_DOFS)
}

/// [`geometric_velocity`] with a coarsest level of more than `factored` DOFs aggregated
/// further.
pub fn geometric_velocity_factoring<const D: usize>(
    mesh: &Mesh<D>,
    dofs: &DofMap<D>,
    lead: usize,
    factored: usize,
) -> Option<Coarsening> {
    let levels = node_levels(mesh, COARSE_NODES);
    if levels.is_empty() {
        return None;
    }
    let (prolongators, blocks, coarsest) = geometric(dofs, lead, &levels);
    let below = (coarsest.len() > factored).then(|| Below {
        nullspace: rigid_modes_at(mesh, dofs, &coarsest),
        k: rigid_modes::count(D),
    });
    Some(Coarsening::Geometric {
        prolongators,
        blocks,
        below,
    })
}

/// The geometric coarsening of a scalar nodal operator, None when the mesh has no nested
/// levels: P is the node stencils themselves.
pub fn geometric_scalar<const D: usize>(mesh: &Mesh<D>) -> Option<Coarsening> {
    let levels = node_levels(mesh, COARSE_NODES);
    if levels.is_empty() {
        return None;
    }
    let mut fine_nodes = mesh.n_nodes();
    let mut prolongators = Vec::new();
    let mut blocks = Vec::new();
    for level in &levels {
        let nc = level.fine_of.len();
        let t = (0..fine_nodes)
            .flat_map(|i| {
                level.stencil[level.ptr[i]..level.ptr[i + 1]]
                    .iter()
                    .map(move |&(c, w)| (i, c, w))
            })
            .collect();
        prolongators.push(Csr::from_triplets(fine_nodes, nc, t));
        blocks.push(Blocks::scalar(nc));
        fine_nodes = nc;
    }
    let below = (fine_nodes > FACTORED_DOFS).then(|| Below {
        nullspace: vec![1.0; fine_nodes],
        k: 1,
    });
    Some(Coarsening::Geometric {
        prolongators,
        blocks,
        below,
    })
}

/// The node blocks and the coarsening of a scalar nodal operator with `n` rows on `mesh` (the
/// damage matrix H): geometric levels where the mesh has them (P the node stencils
/// themselves), else smoothed aggregation with the constants as near-nullspace.
pub fn scalar_levels<const D: usize>(mesh: &Mesh<D>, n: usize) -> (Blocks, Coarsening) {
    let coarsening = geometric_scalar(mesh).unwrap_or_else(|| Coarsening::Aggregation {
        nullspace: vec![1.0; n],
        k: 1,
    });
    (Blocks::scalar(n), coarsening)
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

/// One coarsening of a nested node hierarchy: the coarse nodes are nodes of the finer level
/// (`fine_of[c]`), and each finer node's P1 stencil (coarse node, weight) interpolates.
struct NodeLevel {
    fine_of: Vec<usize>,
    /// CSR over the finer level's nodes.
    ptr: Vec<usize>,
    stencil: Vec<(usize, f64)>,
}

impl NodeLevel {
    fn from_stencils(
        fine_of: Vec<usize>,
        visit: impl FnOnce(&mut dyn FnMut(&[(usize, f64)])),
    ) -> Self {
        let (mut ptr, mut stencil) = (vec![0], Vec::new());
        visit(&mut |w: &[(usize, f64)]| {
            stencil.extend(w.iter().copied().filter(|&(_, v)| v != 0.0));
            ptr.push(stencil.len());
        });
        NodeLevel {
            fine_of,
            ptr,
            stencil,
        }
    }
}

/// The node levels of a mesh, finest first: its red refinements (the mesh as given is the
/// coarsest), else the halvings of a generated rectangle or box while every cell count is
/// even and the finer level has more than `coarse_nodes` nodes. Empty if there are none.
fn node_levels<const D: usize>(mesh: &Mesh<D>, coarse_nodes: usize) -> Vec<NodeLevel> {
    if !mesh.nesting.is_empty() {
        return mesh
            .nesting
            .iter()
            .rev()
            .map(|nest| {
                let nc = nest.coarse_nodes;
                NodeLevel::from_stencils((0..nc).collect(), |visit| {
                    for i in 0..nc {
                        visit(&[(i, 1.0)]);
                    }
                    // A midpoint of two coarse nodes (red refinement), or, after bisections,
                    // of nodes made earlier in the same level: the mean of their stencils.
                    let mut made: Vec<Vec<(usize, f64)>> = Vec::new();
                    for &[a, b] in &nest.midpoints {
                        let mut w: Vec<(usize, f64)> = Vec::with_capacity(2);
                        for end in [a, b] {
                            match end.checked_sub(nc) {
                                None => add(&mut w, end, 0.5),
                                Some(k) => {
                                    for &(c, x) in &made[k] {
                                        add(&mut w, c, 0.5 * x);
                                    }
                                }
                            }
                        }
                        visit(&w);
                        made.push(w);
                    }
                })
            })
            .collect();
    }
    let mut levels = Vec::new();
    if let Some(mut fine) = mesh.lattice {
        let nodes = |l: &Lattice| l.cells.iter().map(|c| c + 1).product::<usize>();
        while fine.cells.iter().all(|c| c % 2 == 0) && nodes(&fine) > coarse_nodes {
            let coarse = Lattice {
                size: fine.size,
                cells: fine.cells.map(|c| c / 2),
            };
            let [fx, fy, _] = fine.cells;
            let [cx, cy, cz] = coarse.cells;
            let mut fine_of = Vec::with_capacity(nodes(&coarse));
            for k in 0..=cz {
                for j in 0..=cy {
                    for i in 0..=cx {
                        fine_of.push(2 * i + (fx + 1) * (2 * j + (fy + 1) * 2 * k));
                    }
                }
            }
            levels.push(NodeLevel::from_stencils(fine_of, |visit| {
                lattice_stencils(&coarse, &fine, visit)
            }));
            fine = coarse;
        }
    } else if let Some(mut fine) = mesh.grid {
        let nodes = |g: &Grid| (g.nx + 1) * (g.ny + 1);
        while fine.pattern != MeshPattern::Cross
            && fine.nx % 2 == 0
            && fine.ny % 2 == 0
            && nodes(&fine) > coarse_nodes
        {
            let coarse = Grid {
                nx: fine.nx / 2,
                ny: fine.ny / 2,
                ..fine
            };
            let mut fine_of = Vec::with_capacity(nodes(&coarse));
            for j in 0..=coarse.ny {
                for i in 0..=coarse.nx {
                    fine_of.push(2 * j * (fine.nx + 1) + 2 * i);
                }
            }
            levels.push(NodeLevel::from_stencils(fine_of, |visit| {
                grid_stencils(&coarse, &fine, visit)
            }));
            fine = coarse;
        }
    }
    levels
}

/// Adds weight `x` of coarse node `c` to the stencil `w`.
fn add(w: &mut Vec<(usize, f64)>, c: usize, x: f64) {
    match w.iter_mut().find(|e| e.0 == c) {
        Some(e) => e.1 += x,
        None => w.push((c, x)),
    }
}

/// The prolongators of the node levels, finest first, each coarser level's blocks, and the
/// coarsest level's DOFs as (finest node, component).
///
/// A level's DOFs are the finest level's free DOFs (below `lead`) at the finest nodes that
/// its nodes are, in their frames; on each level they are numbered node by node.
fn geometric<const D: usize>(
    dofs: &DofMap<D>,
    lead: usize,
    levels: &[NodeLevel],
) -> (Vec<Csr>, Vec<Blocks>, Vec<(usize, usize)>) {
    let axis = |node: usize, r: usize| -> [f64; D] {
        match dofs.frame(node) {
            Some(rows) => rows[r],
            None => std::array::from_fn(|c| if c == r { 1.0 } else { 0.0 }),
        }
    };
    // The finest level: its free DOFs as (finest node, component) in free order, and per
    // node its (component, level DOF) list.
    let n_nodes = dofs.slot.len() / D;
    let mut level_dofs = vec![(0usize, 0usize); lead];
    let mut at: Vec<Vec<(usize, usize)>> = vec![Vec::new(); n_nodes];
    for (dof, s) in dofs.slot.iter().enumerate() {
        if let Slot::Free(f) = *s {
            if f < lead {
                level_dofs[f] = (dof / D, dof % D);
                at[dof / D].push((dof % D, f));
            }
        }
    }
    // The finest node of each node of the current level.
    let mut finest: Vec<usize> = (0..n_nodes).collect();
    let mut prolongators = Vec::new();
    let mut coarse_blocks = Vec::new();
    for level in levels {
        let nc = level.fine_of.len();
        let mut coarse_dofs = Vec::new();
        let mut coarse_at: Vec<Vec<(usize, usize)>> = vec![Vec::new(); nc];
        let mut block_of = Vec::new();
        for (c, &f) in level.fine_of.iter().enumerate() {
            for &(r, _) in &at[f] {
                coarse_at[c].push((r, coarse_dofs.len()));
                coarse_dofs.push((finest[f], r));
                block_of.push(c as u32);
            }
        }
        let mut t = Vec::new();
        for (fine_node, list) in at.iter().enumerate() {
            let stencil = &level.stencil[level.ptr[fine_node]..level.ptr[fine_node + 1]];
            for &(r, fi) in list {
                let ti = axis(finest[fine_node], r);
                for &(c, w) in stencil {
                    for &(s, ci) in &coarse_at[c] {
                        let te = axis(finest[level.fine_of[c]], s);
                        let v: f64 = (0..D).map(|k| ti[k] * te[k]).sum();
                        if v != 0.0 {
                            t.push((fi, ci, w * v));
                        }
                    }
                }
            }
        }
        prolongators.push(Csr::from_triplets(level_dofs.len(), coarse_dofs.len(), t));
        coarse_blocks.push(Blocks::from_block_of(&block_of, nc));
        finest = level.fine_of.iter().map(|&f| finest[f]).collect();
        level_dofs = coarse_dofs;
        at = coarse_at;
    }
    (prolongators, coarse_blocks, level_dofs)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::{Cholesky, CholeskyPlan};

    /// The values of the linear field v(x) = A x + b at the given nodes, D per node.
    fn linear_field<const D: usize>(nodes: &[[f64; D]], seed: f64) -> Vec<f64> {
        let a = |r: usize, c: usize| ((r * D + c) as f64 * 0.731 + seed).sin();
        nodes
            .iter()
            .flat_map(|x| {
                (0..D).map(move |r| {
                    (0..D).map(|c| a(r, c) * x[c]).sum::<f64>() + a(r, r) * 0.3 + seed
                })
            })
            .collect()
    }

    /// P1 interpolation is exact for linear fields: on every level, P times the field at the
    /// coarse nodes is the field at the finer nodes (all DOFs free, node-major order).
    fn prolongators_reproduce_linear_fields<const D: usize>(mesh: &Mesh<D>, expect_levels: usize) {
        let dofs = DofMap::all_free(mesh);
        let levels = node_levels(mesh, 10);
        assert_eq!(levels.len(), expect_levels);
        let (ps, blocks, coarsest) = geometric(&dofs, dofs.n_free(), &levels);
        // The coarsest DOFs are (finest node, component), node-major here, and their rigid
        // modes are the finest modes at those DOFs (the near-nullspace for aggregating below).
        let k = rigid_modes::count(D);
        let (fine_modes, coarse_modes) = (
            rigid_modes(mesh, &dofs),
            rigid_modes_at(mesh, &dofs, &coarsest),
        );
        for (j, &(node, r)) in coarsest.iter().enumerate() {
            let f = D * node + r;
            assert_eq!(
                coarse_modes[j * k..(j + 1) * k],
                fine_modes[f * k..(f + 1) * k]
            );
        }
        let mut finest: Vec<usize> = (0..mesh.n_nodes()).collect();
        for ((level, p), b) in levels.iter().zip(&ps).zip(&blocks) {
            let fine_x: Vec<[f64; D]> = finest.iter().map(|&i| mesh.nodes[i]).collect();
            finest = level.fine_of.iter().map(|&f| finest[f]).collect();
            let coarse_x: Vec<[f64; D]> = finest.iter().map(|&i| mesh.nodes[i]).collect();
            assert_eq!((p.nrows, p.ncols), (D * fine_x.len(), D * coarse_x.len()));
            assert_eq!(b.len(), coarse_x.len());
            for seed in [0.0, 1.3] {
                let mut pv = vec![0.0; p.nrows];
                p.mul_vec(&linear_field(&coarse_x, seed), &mut pv);
                for (u, v) in pv.iter().zip(linear_field(&fine_x, seed)) {
                    assert!((u - v).abs() < 1e-12, "{u} vs {v}");
                }
            }
        }
        let last: Vec<(usize, usize)> = finest
            .iter()
            .flat_map(|&i| (0..D).map(move |r| (i, r)))
            .collect();
        assert_eq!(coarsest, last);
    }

    #[test]
    fn halved_grids_boxes_and_refinements_prolongate_exactly() {
        for pattern in [MeshPattern::Diagonal, MeshPattern::AntiDiagonal] {
            // 8 × 4 cells: halved to 4 × 2 and 2 × 1.
            prolongators_reproduce_linear_fields(&Mesh::rectangle(2.0, 1.0, 8, 4, pattern), 2);
        }
        prolongators_reproduce_linear_fields(&Mesh::cuboid(2.0, 1.0, 1.0, 4, 2, 2), 1);
        // An odd count stops the halving; the cross pattern is not nested.
        assert!(node_levels(&Mesh::cuboid(1.0, 1.0, 1.0, 4, 3, 4), 10).is_empty());
        let cross = Mesh::rectangle(1.0, 1.0, 4, 4, MeshPattern::Cross);
        assert!(node_levels(&cross, 10).is_empty());
        let refined = Mesh::rectangle(1.0, 1.0, 3, 3, MeshPattern::Diagonal)
            .refine()
            .refine();
        prolongators_reproduce_linear_fields(&refined, 2);
    }

    /// Bisected meshes nest too: levels whose midpoints have earlier midpoints as ends (a
    /// node made by the second of several bisections) prolongate linear fields exactly.
    #[test]
    fn chains_of_bisections_prolongate_exactly() {
        fn chained<const D: usize>(mesh: Mesh<D>, rounds: usize) -> Mesh<D> {
            let mut b = crate::mesh::bisect::Bisection::new(&mesh);
            let mut midpoints = Vec::new();
            for r in 0..rounds {
                let marked: Vec<usize> =
                    (0..b.mesh().n_cells()).filter(|c| c % 3 != r % 3).collect();
                midpoints.extend(b.refine(&marked).midpoints.iter().map(|&(_, e)| e));
            }
            let mut fine = b.mesh().clone();
            let n0 = mesh.n_nodes();
            assert!(
                midpoints.iter().any(|e| e.iter().any(|&v| v >= n0)),
                "chained ends"
            );
            fine.nesting = vec![crate::mesh::Nesting {
                coarse_nodes: n0,
                midpoints,
            }];
            fine
        }
        prolongators_reproduce_linear_fields(
            &chained(Mesh::rectangle(2.0, 1.0, 4, 2, MeshPattern::Diagonal), 3),
            1,
        );
        prolongators_reproduce_linear_fields(&chained(Mesh::cuboid(1.0, 1.0, 1.0, 2, 2, 2), 4), 1);
    }

    /// A P1-type operator on `mesh` with `b` DOFs per node: DOFs p ≠ q coupled when their
    /// nodes are equal or share a cell, by −(½ + ¼ sin(p + 1.7 q)) for p < q (generic values,
    /// so no fill entry of the factor cancels to zero), and 1 + the row's absolute sum on the
    /// diagonal (diagonally dominant: SPD). The pattern of K_II (b = D) or of H (b = 1).
    fn node_operator<const D: usize>(mesh: &Mesh<D>, b: usize) -> Csr {
        let mut nodes = std::collections::BTreeSet::new();
        for cell in mesh.cells() {
            for &i in cell {
                for &j in cell {
                    nodes.insert((i, j));
                }
            }
        }
        let n = b * mesh.n_nodes();
        let mut t = Vec::new();
        let mut diagonal = vec![1.0; n];
        for &(i, j) in &nodes {
            for r in 0..b {
                for c in 0..b {
                    let (p, q) = (b * i + r, b * j + c);
                    if p != q {
                        let v = -(0.5 + 0.25 * (p.min(q) as f64 + 1.7 * p.max(q) as f64).sin());
                        t.push((p, q, v));
                        diagonal[p] -= v;
                    }
                }
            }
        }
        t.extend(diagonal.iter().enumerate().map(|(p, &d)| (p, p, d)));
        Csr::from_triplets(n, n, t)
    }

    /// Entries of the Cholesky factor of `a`'s pattern in the order `forward` (row i of the
    /// factored matrix is row `forward[i]` of `a`), by graph elimination: column i of L holds
    /// i, the later neighbours of i and the columns of its children in the elimination tree.
    fn elimination_fill(a: &Csr, forward: &[usize]) -> usize {
        let n = a.nrows;
        let mut position = vec![0; n];
        for (i, &f) in forward.iter().enumerate() {
            position[f] = i;
        }
        let mut column: Vec<std::collections::BTreeSet<usize>> = vec![Default::default(); n];
        for r in 0..n {
            for &c in &a.indices[a.indptr[r]..a.indptr[r + 1]] {
                let (i, j) = (position[r], position[c as usize]);
                if i < j {
                    column[i].insert(j);
                }
            }
        }
        let mut entries = 0;
        for i in 0..n {
            let below = std::mem::take(&mut column[i]);
            entries += 1 + below.len();
            if let Some(&parent) = below.iter().next() {
                column[parent].extend(below.iter().skip(1));
            }
        }
        entries
    }

    /// Nonzero values on and below the diagonal of a supernodal factor: supernode s holds
    /// columns begin..end as a column-major block whose rows are those columns, then its row
    /// pattern.
    fn lower_nonzeros(factor: &Cholesky) -> usize {
        let l = factor.supernodal();
        let s = l.symbolic();
        let (begin, end) = (s.supernode_begin(), s.supernode_end());
        let val_ptr = s.col_ptr_for_val();
        let mut count = 0;
        for k in 0..s.n_supernodes() {
            let cols = end[k] - begin[k];
            let block = &l.values()[val_ptr[k]..val_ptr[k + 1]];
            let rows = block.len() / cols;
            for j in 0..cols {
                count += block[j * rows + j..(j + 1) * rows]
                    .iter()
                    .filter(|v| **v != 0.0)
                    .count();
            }
        }
        count
    }

    /// The symbolic analysis sizes the factor before any numeric work: the factor made from a
    /// plan stores the plan's nnz(L) entries, exactly as many of them nonzero as graph
    /// elimination in the factor's order predicts (the rest are the explicit zeros of
    /// faer's dense supernodal blocks), and the plan's bytes hold at least its values; the
    /// least-fill plan is the smaller of AMD's and nested dissection's. 2D and 3D, vector
    /// and scalar operators.
    #[test]
    fn a_plan_sizes_its_factor_before_the_numeric_work() {
        use crate::linalg::cholesky::Ordering;
        let square = Mesh::rectangle(1.0, 1.0, 12, 12, MeshPattern::Diagonal);
        let cube = Mesh::cuboid(1.0, 1.0, 1.0, 4, 4, 4);
        let operators = [
            node_operator(&square, 2),
            node_operator(&square, 1),
            node_operator(&cube, 3),
            node_operator(&cube, 1),
        ];
        for a in &operators {
            let lower = a.lower_csc();
            let nnz = |o| CholeskyPlan::by(lower.as_ref(), o).unwrap().nnz_l();
            let least = CholeskyPlan::least_fill(lower.as_ref()).unwrap();
            assert_eq!(
                least.nnz_l(),
                nnz(Ordering::Amd).min(nnz(Ordering::NestedDissection))
            );
            for plan in [CholeskyPlan::amd(lower.as_ref()).unwrap(), least] {
                let (entries, bytes) = (plan.nnz_l(), plan.factor_bytes());
                let factor = Cholesky::from_plan(plan, lower.as_ref()).unwrap();
                assert_eq!(factor.nnz_l(), entries);
                let nonzero = lower_nonzeros(&factor);
                let fill = elimination_fill(a, &factor.forward());
                assert_eq!(nonzero, fill, "n = {}", a.nrows);
                assert!(fill <= entries && bytes >= 8 * entries as u64);
            }
        }
    }
}
