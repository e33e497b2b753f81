//! Degrees of freedom of the velocity: D per node (components interleaved: dof = D·node + c).
//! Γ1 nodes are clamped (all components, "Dirichlet wins"); Γ3 nodes have zero normal
//! velocity w_i · n_i = 0, and their tangential components are *contact* DOFs carrying the
//! non-smooth friction term. Free DOFs are numbered interior first, contact last, so the
//! contact block is the trailing block of every free-DOF matrix.
//!
//! Contact frames (docs/src/explanation/numerics.md#contact-frames): n_i is the unit vector along
//! Σ_F |F| ν_F over the Γ3 facets F at node i, and ω_i = Σ_F |F| / D. When n_i is a
//! coordinate direction ±e_c (a straight Γ3 along an axis, as on rectangles) the node keeps
//! the Cartesian components and component c is the fixed one; otherwise its D DOFs are the
//! components in a rotated orthonormal frame (n_i, t_1, …): the first is fixed, the others
//! are contact DOFs. The free-DOF operators are then Qᵀ K Q with Q the block rotation.

#![allow(clippy::needless_range_loop)] // Index loops over vertices and components spell out the formulas.

use crate::linalg::par;
use crate::mesh::Mesh;
use crate::problem::{BoundaryKind, BoundaryPart};

/// Where a DOF lives in the free-DOF numbering.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Slot {
    Fixed,
    Free(usize),
}

/// A tangential DOF on Γ3.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactDof {
    pub node: usize,
    /// DOF index D·node + local component.
    pub dof: usize,
    /// ω_i: |F|/D summed over the Γ3 facets at the node (nodal trapezoid rule).
    pub weight: f64,
}

/// A node whose DOFs are components in a rotated frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame<const D: usize> {
    pub node: usize,
    /// Orthonormal rows: n_i first, then the tangents. Local component r = rows[r] · v.
    pub rows: [[f64; D]; D],
}

#[derive(Debug, Clone)]
pub struct DofMap<const D: usize = 2> {
    /// Per DOF (D·node + component in the node's frame).
    pub slot: Vec<Slot>,
    pub n_interior: usize,
    /// Contact DOFs in free-numbering order (free index n_interior + position).
    pub contact: Vec<ContactDof>,
    /// The nodes with rotated frames, by increasing node.
    pub frames: Vec<Frame<D>>,
    /// Index into `frames` per node, if rotated.
    frame_of: Vec<Option<u32>>,
    /// n_i at every unclamped Γ3 node, by increasing node.
    pub normals: Vec<(usize, [f64; D])>,
}

impl<const D: usize> DofMap<D> {
    pub fn new(mesh: &Mesh<D>, parts: &[BoundaryPart]) -> DofMap<D> {
        let n = mesh.n_nodes();
        let mut clamped = vec![false; n];
        let mut normal = vec![[0.0; D]; n];
        let mut on_contact = vec![false; n];
        let mut weight = vec![0.0; n];
        for f in &mesh.facets {
            match f.part.map(|p| &parts[p].kind) {
                Some(BoundaryKind::Clamped) => f.nodes.iter().for_each(|&i| clamped[i] = true),
                Some(BoundaryKind::Contact) => {
                    for &i in &f.nodes {
                        on_contact[i] = true;
                        for c in 0..D {
                            normal[i][c] += f.measure * f.normal[c];
                        }
                        weight[i] += f.measure / D as f64;
                    }
                }
                _ => {}
            }
        }
        let mut slot = vec![Slot::Fixed; D * n];
        let mut n_interior = 0;
        let mut contact = Vec::new();
        let mut frames = Vec::new();
        let mut frame_of = vec![None; n];
        let mut normals = Vec::new();
        for i in 0..n {
            if clamped[i] {
                continue;
            }
            // The local component that is fixed, if any.
            let mut fixed = None;
            if on_contact[i] {
                let len = normal[i].iter().map(|v| v * v).sum::<f64>().sqrt();
                let ni = normal[i].map(|v| v / len);
                normals.push((i, ni));
                let axis = (0..D).find(|&c| (0..D).all(|d| d == c || ni[d] == 0.0));
                match axis {
                    Some(c) => fixed = Some(c),
                    None => {
                        frame_of[i] = Some(frames.len() as u32);
                        frames.push(Frame {
                            node: i,
                            rows: frame(ni),
                        });
                        fixed = Some(0);
                    }
                }
            }
            for c in 0..D {
                let dof = D * i + c;
                if fixed == Some(c) {
                    continue;
                }
                if fixed.is_some() {
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
            frames,
            frame_of,
            normals,
        }
    }

    /// Every DOF free (for tests of the unconstrained operators).
    pub fn all_free(mesh: &Mesh<D>) -> DofMap<D> {
        let n = D * mesh.n_nodes();
        DofMap {
            slot: (0..n).map(Slot::Free).collect(),
            n_interior: n,
            contact: Vec::new(),
            frames: Vec::new(),
            frame_of: vec![None; mesh.n_nodes()],
            normals: Vec::new(),
        }
    }

    pub fn n_free(&self) -> usize {
        self.n_interior + self.contact.len()
    }

    pub fn n_contact(&self) -> usize {
        self.contact.len()
    }

    /// The node and component (in its frame) of each free DOF, by free index.
    pub fn owners(&self) -> Vec<(usize, usize)> {
        let mut owner = vec![(0, 0); self.n_free()];
        for (dof, slot) in self.slot.iter().enumerate() {
            if let Slot::Free(f) = *slot {
                owner[f] = (dof / D, dof % D);
            }
        }
        owner
    }

    /// The rotated frame of a node, if it has one.
    #[inline]
    pub fn frame(&self, node: usize) -> Option<&[[f64; D]; D]> {
        self.frame_of[node].map(|k| &self.frames[k as usize].rows)
    }

    /// The Cartesian direction of a contact DOF (its tangent t).
    pub fn direction(&self, cd: &ContactDof) -> [f64; D] {
        let c = cd.dof - D * cd.node;
        match self.frame(cd.node) {
            Some(rows) => rows[c],
            None => std::array::from_fn(|d| if d == c { 1.0 } else { 0.0 }),
        }
    }

    /// Scatter a free-DOF vector into a global Cartesian nodal vector (fixed DOFs zero).
    pub fn to_global(&self, free: &[f64], global: &mut [f64]) {
        par::for_each_chunk_mut(global, par::VECTOR_CHUNK, |start, chunk| {
            for (g, s) in chunk.iter_mut().zip(&self.slot[start..]) {
                *g = match *s {
                    Slot::Free(f) => free[f],
                    Slot::Fixed => 0.0,
                };
            }
        });
        for fr in &self.frames {
            let local: [f64; D] = std::array::from_fn(|r| global[D * fr.node + r]);
            for c in 0..D {
                global[D * fr.node + c] = (0..D).map(|r| fr.rows[r][c] * local[r]).sum();
            }
        }
    }

    /// Gather the free DOFs of a global Cartesian vector (its components in each frame).
    pub fn to_free(&self, global: &[f64], free: &mut [f64]) {
        for (g, s) in global.iter().zip(&self.slot) {
            if let Slot::Free(f) = *s {
                free[f] = *g;
            }
        }
        for fr in &self.frames {
            let v = &global[D * fr.node..D * fr.node + D];
            for r in 0..D {
                if let Slot::Free(f) = self.slot[D * fr.node + r] {
                    free[f] = (0..D).map(|c| fr.rows[r][c] * v[c]).sum();
                }
            }
        }
    }
}

/// An orthonormal frame (n, t, …) for a unit normal n that is not a coordinate direction;
/// tangents are made deterministic by taking the component of largest magnitude positive.
fn frame<const D: usize>(n: [f64; D]) -> [[f64; D]; D] {
    let mut rows = [[0.0; D]; D];
    rows[0] = n;
    let positive = |mut t: [f64; D]| {
        let big = (0..D).fold(0, |b, c| if t[c].abs() > t[b].abs() { c } else { b });
        if t[big] < 0.0 {
            t.iter_mut().for_each(|v| *v = -*v);
        }
        t
    };
    match D {
        2 => rows[1] = positive(std::array::from_fn(|c| if c == 0 { -n[1] } else { n[0] })),
        _ => {
            // t1: the coordinate axis least aligned with n, made orthogonal; t2 = n × t1.
            let k = (0..D).fold(0, |b, c| if n[c].abs() < n[b].abs() { c } else { b });
            let mut t: [f64; D] = std::array::from_fn(|c| if c == k { 1.0 } else { 0.0 });
            let dot = n[k];
            t.iter_mut().zip(&n).for_each(|(v, nc)| *v -= dot * nc);
            let len = t.iter().map(|v| v * v).sum::<f64>().sqrt();
            let t1 = positive(t.map(|v| v / len));
            rows[1] = t1;
            rows[2] = std::array::from_fn(|c| {
                let (a, b) = ((c + 1) % 3, (c + 2) % 3);
                n[a] * t1[b] - n[b] * t1[a]
            });
        }
    }
    rows
}
