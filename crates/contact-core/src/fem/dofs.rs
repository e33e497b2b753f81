//! Degrees of freedom of the velocity: two per node (x, y interleaved: dof = 2·node + c).
//! Γ1 nodes are clamped (both components, "Dirichlet wins"); Γ3 nodes have zero normal
//! velocity, and their tangential component is a *contact* DOF carrying the non-smooth
//! friction term. Free DOFs are numbered interior first, contact last, so the contact block
//! is the trailing block of every free-DOF matrix.

use crate::mesh::Mesh;
use crate::problem::{BoundaryKind, BoundaryPart};

/// Where a global DOF lives in the free-DOF numbering.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Slot {
    Fixed,
    Free(usize),
}

/// A tangential DOF on Γ3.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactDof {
    pub node: usize,
    /// Global DOF index (2·node + tangential component).
    pub dof: usize,
    /// ω_i: half the total length of the Γ3 edges at the node (nodal trapezoid rule).
    pub weight: f64,
}

#[derive(Debug, Clone)]
pub struct DofMap {
    pub slot: Vec<Slot>,
    pub n_interior: usize,
    /// Contact DOFs in free-numbering order (free index n_interior + position).
    pub contact: Vec<ContactDof>,
}

impl DofMap {
    pub fn new(mesh: &Mesh, parts: &[BoundaryPart]) -> DofMap {
        let n = mesh.n_nodes();
        let mut clamped = vec![false; n];
        // Per node: fixed components from Γ3 normals, and the Γ3 weight.
        let mut normal_fixed = vec![[false; 2]; n];
        let mut weight = vec![0.0; n];
        for e in &mesh.boundary_edges {
            match e.part.map(|p| &parts[p].kind) {
                Some(BoundaryKind::Clamped) => e.nodes.iter().for_each(|&i| clamped[i] = true),
                Some(BoundaryKind::Contact) => {
                    // Rectangle edges are axis-aligned: the normal is a coordinate direction.
                    let c = if e.normal[0].abs() > 0.5 { 0 } else { 1 };
                    for &i in &e.nodes {
                        normal_fixed[i][c] = true;
                        weight[i] += 0.5 * e.length;
                    }
                }
                _ => {}
            }
        }
        let mut slot = vec![Slot::Fixed; 2 * n];
        let mut n_interior = 0;
        let mut contact = Vec::new();
        for i in 0..n {
            if clamped[i] {
                continue;
            }
            let fixed = normal_fixed[i];
            let on_contact = fixed[0] || fixed[1];
            for (c, &normal) in fixed.iter().enumerate() {
                let dof = 2 * i + c;
                if normal {
                    continue;
                }
                if on_contact {
                    // Tangential DOF of a contact node (a corner with two normals has none).
                    contact.push(ContactDof {
                        node: i,
                        dof,
                        weight: weight[i],
                    });
                } else {
                    slot[dof] = Slot::Free(n_interior);
                    n_interior += 1;
                }
            }
        }
        for (k, cd) in contact.iter().enumerate() {
            slot[cd.dof] = Slot::Free(n_interior + k);
        }
        DofMap {
            slot,
            n_interior,
            contact,
        }
    }

    /// Every DOF free (for tests of the unconstrained operators).
    pub fn all_free(mesh: &Mesh) -> DofMap {
        let n = 2 * mesh.n_nodes();
        DofMap {
            slot: (0..n).map(Slot::Free).collect(),
            n_interior: n,
            contact: Vec::new(),
        }
    }

    pub fn n_free(&self) -> usize {
        self.n_interior + self.contact.len()
    }

    pub fn n_contact(&self) -> usize {
        self.contact.len()
    }

    /// Scatter a free-DOF vector into a global nodal vector (fixed DOFs zero).
    pub fn to_global(&self, free: &[f64], global: &mut [f64]) {
        for (g, s) in global.iter_mut().zip(&self.slot) {
            *g = match *s {
                Slot::Free(f) => free[f],
                Slot::Fixed => 0.0,
            };
        }
    }

    /// Gather the free DOFs of a global vector.
    pub fn to_free(&self, global: &[f64], free: &mut [f64]) {
        for (g, s) in global.iter().zip(&self.slot) {
            if let Slot::Free(f) = *s {
                free[f] = *g;
            }
        }
    }
}
