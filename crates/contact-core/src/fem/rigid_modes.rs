//! The rigid-body modes of the velocity space written on the free DOFs: the near-nullspace
//! of the velocity operator K that smoothed aggregation interpolates exactly
//! ([`crate::linalg::multigrid::aggregation`]).
//!
//! In D dimensions there are D translations and D(D−1)/2 rotations (3 modes in 2D, 6 in 3D),
//! taken about the mesh's centroid (for a well-scaled QR per aggregate). A free DOF of a node
//! with a rotated contact frame is the component rows[r] · v of the Cartesian mode v; fixed
//! DOFs (Γ1, the Γ3 normal) are simply absent, so the modes are those of the constrained
//! space restricted to each aggregate.

#![allow(clippy::needless_range_loop)] // Index loops over nodes, blocks and components spell out the formulas.

use super::{DofMap, Slot};
use crate::linalg::multigrid::Blocks;
use crate::mesh::Mesh;

/// Number of rigid-body modes in D dimensions.
pub const fn count(d: usize) -> usize {
    d * (d + 1) / 2
}

/// The modes on the free DOFs, n_free × count(D), row-major.
pub fn rigid_modes<const D: usize>(mesh: &Mesh<D>, dofs: &DofMap<D>) -> Vec<f64> {
    let k = count(D);
    let centre = centroid(mesh);
    let mut out = vec![0.0; dofs.n_free() * k];
    for i in 0..mesh.n_nodes() {
        for r in 0..D {
            if let Slot::Free(f) = dofs.slot[D * i + r] {
                write_modes(mesh, dofs, centre, (i, r), &mut out[f * k..(f + 1) * k]);
            }
        }
    }
    out
}

/// The modes at the listed (node, component) DOFs, in list order (a coarse level of a
/// nested hierarchy whose DOFs are such finest DOFs, [`crate::fem::multilevel`]):
/// list.len() × count(D), row-major, the rows of [`rigid_modes`] at those DOFs.
pub fn rigid_modes_at<const D: usize>(
    mesh: &Mesh<D>,
    dofs: &DofMap<D>,
    list: &[(usize, usize)],
) -> Vec<f64> {
    let k = count(D);
    let centre = centroid(mesh);
    let mut out = vec![0.0; list.len() * k];
    for (j, &dof) in list.iter().enumerate() {
        write_modes(mesh, dofs, centre, dof, &mut out[j * k..(j + 1) * k]);
    }
    out
}

fn centroid<const D: usize>(mesh: &Mesh<D>) -> [f64; D] {
    let n = mesh.n_nodes().max(1);
    let mut centre = [0.0; D];
    for p in &mesh.nodes {
        for c in 0..D {
            centre[c] += p[c] / n as f64;
        }
    }
    centre
}

/// The count(D) modes' values at component r of node i (in its contact frame, if any).
fn write_modes<const D: usize>(
    mesh: &Mesh<D>,
    dofs: &DofMap<D>,
    centre: [f64; D],
    (i, r): (usize, usize),
    out: &mut [f64],
) {
    let p = mesh.nodes[i];
    let x: [f64; D] = std::array::from_fn(|c| p[c] - centre[c]);
    // Cartesian modes at this node: modes[m][c].
    let mut modes = vec![[0.0; D]; count(D)];
    for c in 0..D {
        modes[c][c] = 1.0;
    }
    if D == 2 {
        modes[2][0] = -x[1];
        modes[2][1] = x[0];
    } else {
        // Rotations about x, y, z: ω × x.
        for (m, (a, b)) in [(1usize, 2usize), (2, 0), (0, 1)].into_iter().enumerate() {
            modes[D + m][a] = -x[b];
            modes[D + m][b] = x[a];
        }
    }
    for (m, v) in modes.iter().enumerate() {
        out[m] = match dofs.frame(i) {
            Some(rows) => (0..D).map(|c| rows[r][c] * v[c]).sum(),
            None => v[r],
        };
    }
}

/// The node blocks of the free DOFs: each node's free components (none for clamped nodes).
pub fn node_blocks<const D: usize>(mesh: &Mesh<D>, dofs: &DofMap<D>) -> Blocks {
    let block_of: Vec<u32> = dofs.owners().iter().map(|&(node, _)| node as u32).collect();
    Blocks::from_block_of(&block_of, mesh.n_nodes())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fem::{assembly, Geometry};
    use crate::mesh::{Mesh, MeshPattern};

    /// K annihilates every rigid mode of the unconstrained body: the modes are exact.
    #[test]
    fn modes_are_in_the_kernel_of_the_unconstrained_operator() {
        let mesh = Mesh::rectangle(2.0, 1.0, 6, 3, MeshPattern::Diagonal);
        let geo = Geometry::new(&mesh);
        let dofs = DofMap::all_free(&mesh);
        let k = assembly::viscous_stiffness(&mesh, &geo, &dofs, 2.0, 2.0);
        let modes = rigid_modes(&mesh, &dofs);
        let n = dofs.n_free();
        for m in 0..3 {
            let v: Vec<f64> = (0..n).map(|i| modes[i * 3 + m]).collect();
            let mut kv = vec![0.0; n];
            k.mul_vec(&v, &mut kv);
            assert!(kv.iter().all(|x| x.abs() < 1e-12), "mode {m}");
        }
        let box3 = Mesh::cuboid(1.0, 1.0, 2.0, 2, 2, 4);
        let geo3 = Geometry::new(&box3);
        let dofs3 = DofMap::all_free(&box3);
        let k3 = assembly::viscous_stiffness(&box3, &geo3, &dofs3, 1.0, 0.5);
        let modes3 = rigid_modes(&box3, &dofs3);
        let n3 = dofs3.n_free();
        for m in 0..6 {
            let v: Vec<f64> = (0..n3).map(|i| modes3[i * 6 + m]).collect();
            let mut kv = vec![0.0; n3];
            k3.mul_vec(&v, &mut kv);
            assert!(kv.iter().all(|x| x.abs() < 1e-12), "3D mode {m}");
        }
        assert_eq!(node_blocks(&box3, &dofs3).len(), box3.n_nodes());
    }
}
