//! The checks an input mesh must pass before anything is computed on it, and the boundary
//! facets found on the way. Each failure names the first offending cell, facet or node (in
//! the mesh's order, 0-based), so a user can find it in the file.
//!
//! - every coordinate finite; every cell's vertices distinct and existing;
//! - no degenerate cell: |T| > 1e-12 × (longest edge)^D;
//! - no cell twice; every facet shared by at most two cells (else the mesh is not a manifold);
//! - no fold: at every interior facet the two cells lie on opposite sides of it (two cells on
//!   the same side overlap, as when a node is moved across its neighbours). A cell's vertices
//!   may be listed in either orientation, and the mesh may mix both: the order is a labelling,
//!   not geometry, so only this geometric test says whether cells overlap;
//! - every node in some cell; the cells connected through shared facets (one body).
//!
//! The boundary facets are the faces of exactly one cell, in the order of first appearance
//! (cells in order, and in each cell the face opposite vertex D, D − 1, …, 0).

#![allow(clippy::needless_range_loop)] // Index loops over vertices and components spell out the formulas.

use std::collections::HashMap;

use super::{facet_frame, signed_measure, Facet, Mesh};

/// Relative size (times the longest edge to the power D) below which a cell is degenerate.
pub const DEGENERATE: f64 = 1e-12;

/// Why a mesh was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MeshError {
    #[error("the mesh has no cells")]
    Empty,
    #[error("node {node} has a coordinate that is not a finite number")]
    NotFinite { node: usize },
    #[error("cell {cell} refers to node {node}, but the mesh has {nodes} nodes")]
    MissingNode {
        cell: usize,
        node: usize,
        nodes: usize,
    },
    #[error("cell {cell} uses node {node} twice")]
    RepeatedNode { cell: usize, node: usize },
    #[error("cell {cell} is degenerate (measure {measure:e}, longest edge {edge:e})")]
    Degenerate {
        cell: usize,
        measure: f64,
        edge: f64,
    },
    #[error("cell {cell} is folded onto cell {other}: both lie on the same side of their shared facet (nodes {nodes:?}), so they overlap (a node lies across its neighbours)")]
    Folded {
        cell: usize,
        other: usize,
        nodes: Vec<usize>,
    },
    #[error("cell {cell} repeats cell {first} (the same vertices)")]
    DuplicateCell { cell: usize, first: usize },
    #[error("the facet with nodes {nodes:?} is shared by more than two cells (cell {cell} is the third): the mesh is not a manifold")]
    NonManifold { nodes: Vec<usize>, cell: usize },
    #[error("node {node} belongs to no cell")]
    Unreferenced { node: usize },
    #[error("the mesh is not one connected body: cell {cell} is not connected to cell 0 through shared facets")]
    Disconnected { cell: usize },
    #[error("group \"{group}\": its facet {index} (nodes {nodes:?}) is not a boundary facet of the mesh")]
    NotOnBoundary {
        group: String,
        index: usize,
        nodes: Vec<usize>,
    },
    #[error("group \"{group}\": its facet {index} (nodes {nodes:?}) repeats an earlier facet of the group")]
    DuplicateFacet {
        group: String,
        index: usize,
        nodes: Vec<usize>,
    },
    #[error("the mesh is {found}D, but a {expected}D mesh is needed here")]
    Dimension { found: usize, expected: usize },
    #[error("node {node} has z = {z}, but a 2D mesh lies in the plane z = 0")]
    NotPlanar { node: usize, z: f64 },
    #[error("the mesh has {count} {what}; at most {max} are allowed")]
    TooLarge {
        what: &'static str,
        count: usize,
        max: usize,
    },
}

/// The facet of a cell opposite its local vertex `a`, as a sorted key.
pub(super) fn facet_key<const D: usize>(cell: &[usize], a: usize) -> [usize; D] {
    let mut k = [0; D];
    for (slot, &v) in k.iter_mut().zip(
        cell.iter()
            .enumerate()
            .filter(|&(b, _)| b != a)
            .map(|(_, v)| v),
    ) {
        *slot = v;
    }
    k.sort_unstable();
    k
}

/// A fast hasher for node-index keys (the mesh's own indices, not adversarial in cost: a
/// hostile file can at worst make lookups slower, never wrong).
#[derive(Default, Clone, Copy)]
pub(crate) struct IndexHasher(u64);

impl std::hash::Hasher for IndexHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        bytes.iter().for_each(|&b| self.write_u64(b as u64));
    }
    fn write_u64(&mut self, x: u64) {
        self.0 = (self.0.rotate_left(5) ^ x).wrapping_mul(0x517c_c1b7_2722_0a95);
    }
    fn write_usize(&mut self, x: usize) {
        self.write_u64(x as u64);
    }
}

/// A hash map keyed by node indices.
pub(crate) type IndexMap<K, V> = HashMap<K, V, std::hash::BuildHasherDefault<IndexHasher>>;

/// Every face of every cell, grouped by its vertex set. Face `slot` = (D + 1)·e + (D − a) is
/// cell e's face opposite its vertex a, so slots count the faces in the order they are met
/// (cells in order, faces opposite vertex D, ..., 0). The faces are sorted by lowest vertex
/// (a counting sort), then each lowest vertex's few faces by the others: linear in the
/// faces, where a hash map of them spent most of the checks' time in random accesses.
struct FaceGroups<const D: usize> {
    /// (the other vertices, ascending; slot), lowest vertex by lowest vertex, in slot order
    /// within a vertex set.
    faces: Vec<([u32; D], u32)>,
}

impl<const D: usize> FaceGroups<D> {
    fn new(cells: &[usize], n_nodes: usize) -> FaceGroups<D> {
        let key = |slot: usize| {
            let e = slot / (D + 1);
            facet_key::<D>(&cells[(D + 1) * e..(D + 1) * (e + 1)], D - slot % (D + 1))
        };
        let mut start = vec![0usize; n_nodes + 1];
        for slot in 0..cells.len() {
            start[key(slot)[0] + 1] += 1;
        }
        for v in 0..n_nodes {
            start[v + 1] += start[v];
        }
        let mut next = start.clone();
        let mut faces = vec![([0u32; D], 0u32); cells.len()];
        for slot in 0..cells.len() {
            let k = key(slot);
            let mut rest = [0u32; D];
            for (r, &v) in rest.iter_mut().zip(&k[1..]) {
                *r = v as u32;
            }
            // The lowest vertex, implied by the bucket, is kept in the last place.
            rest[D - 1] = k[0] as u32;
            faces[next[k[0]]] = (rest, slot as u32);
            next[k[0]] += 1;
        }
        // Stable: equal vertex sets keep their slot order.
        for v in 0..n_nodes {
            faces[start[v]..start[v + 1]].sort_by_key(|f| f.0);
        }
        FaceGroups { faces }
    }

    fn len(&self) -> usize {
        self.faces.len()
    }

    /// Each vertex set (sorted) with its faces, in slot order (a face's slot is `.1`).
    fn groups(&self) -> impl Iterator<Item = ([usize; D], &[([u32; D], u32)])> + '_ {
        self.faces.chunk_by(|a, b| a.0 == b.0).map(|group| {
            let rest = group[0].0;
            let mut key = [0usize; D];
            key[0] = rest[D - 1] as usize;
            for (k, &v) in key[1..].iter_mut().zip(&rest[..D - 1]) {
                *k = v as usize;
            }
            (key, group)
        })
    }
}

/// Whether the points `x` and `y` lie on the same side of the facet `f` (its vertices in
/// one order for both). Neither lies on it: each makes a nondegenerate cell with it.
fn same_side<const D: usize>(nodes: &[[f64; D]], f: &[usize; D], x: usize, y: usize) -> bool {
    let side = |v: usize| {
        let mut p = [[0.0; D]; 4];
        for (slot, &i) in p.iter_mut().zip(f.iter().chain([&v])) {
            *slot = nodes[i];
        }
        signed_measure(&p[..=D])
    };
    side(x) * side(y) > 0.0
}

/// Checks the cells (see the module doc) and builds the mesh with its boundary facets.
pub fn build<const D: usize>(
    nodes: Vec<[f64; D]>,
    cells: Vec<usize>,
) -> Result<Mesh<D>, MeshError> {
    let nc = cells.len() / (D + 1);
    if nc == 0 {
        return Err(MeshError::Empty);
    }
    // Faces and nodes are numbered in u32 (FaceGroups).
    let max_cells = (u32::MAX as usize - 1) / (D + 1);
    if nc > max_cells {
        return Err(MeshError::TooLarge {
            what: "cells",
            count: nc,
            max: max_cells,
        });
    }
    if nodes.len() >= u32::MAX as usize {
        return Err(MeshError::TooLarge {
            what: "nodes",
            count: nodes.len(),
            max: u32::MAX as usize - 1,
        });
    }
    if let Some(node) = nodes.iter().position(|p| p.iter().any(|v| !v.is_finite())) {
        return Err(MeshError::NotFinite { node });
    }
    for (e, cell) in cells.chunks_exact(D + 1).enumerate() {
        for (a, &v) in cell.iter().enumerate() {
            if v >= nodes.len() {
                return Err(MeshError::MissingNode {
                    cell: e,
                    node: v,
                    nodes: nodes.len(),
                });
            }
            if cell[..a].contains(&v) {
                return Err(MeshError::RepeatedNode { cell: e, node: v });
            }
        }
        let mut p = [[0.0; D]; 4];
        for (slot, &v) in p.iter_mut().zip(cell) {
            *slot = nodes[v];
        }
        let measure = signed_measure(&p[..=D]);
        let mut edge: f64 = 0.0;
        for a in 0..=D {
            for b in a + 1..=D {
                let l2: f64 = (0..D).map(|c| (p[a][c] - p[b][c]).powi(2)).sum();
                edge = edge.max(l2);
            }
        }
        let edge = edge.sqrt();
        if measure
            .abs()
            .partial_cmp(&(DEGENERATE * edge.powi(D as i32)))
            != Some(std::cmp::Ordering::Greater)
        {
            return Err(MeshError::Degenerate {
                cell: e,
                measure: measure.abs(),
                edge,
            });
        }
    }

    // Duplicate cells: sort the cells by their sorted vertex sets and compare neighbours.
    let mut sorted = cells.clone();
    sorted
        .chunks_exact_mut(D + 1)
        .for_each(|c| c.sort_unstable());
    let key = |e: usize| &sorted[(D + 1) * e..(D + 1) * (e + 1)];
    let mut order: Vec<u32> = (0..nc as u32).collect();
    order.sort_unstable_by(|&a, &b| key(a as usize).cmp(key(b as usize)).then(a.cmp(&b)));
    let mut first_duplicate: Option<(usize, usize)> = None;
    for w in order.windows(2) {
        let (a, b) = (w[0] as usize, w[1] as usize);
        if key(a) == key(b) && first_duplicate.is_none_or(|(cell, _)| b < cell) {
            first_duplicate = Some((b, a));
        }
    }
    drop((order, sorted));
    if let Some((cell, first)) = first_duplicate {
        return Err(MeshError::DuplicateCell { cell, first });
    }

    let faces = FaceGroups::<D>::new(&cells, nodes.len());
    let cell_of = |slot: usize| slot / (D + 1);
    let opposite = |slot: usize| D - slot % (D + 1);
    // The first fold or third cell on a facet in the order the faces are met (cells in
    // order, faces opposite vertex D, ..., 0): the error a face-by-face scan reports.
    let mut first_error: Option<(usize, MeshError)> = None;
    let mut pairs = Vec::with_capacity(faces.len() / 2);
    let mut boundary = vec![false; cells.len()];
    for (key, slots) in faces.groups() {
        let slot = |i: usize| slots.get(i).map(|f| f.1 as usize);
        let s1 = slots[0].1 as usize;
        let Some(s2) = slot(1) else {
            boundary[s1] = true;
            continue;
        };
        let (e1, e2) = (cell_of(s1), cell_of(s2));
        let error = if same_side(
            &nodes,
            &key,
            cells[(D + 1) * e1 + opposite(s1)],
            cells[(D + 1) * e2 + opposite(s2)],
        ) {
            Some((
                s2,
                MeshError::Folded {
                    cell: e2,
                    other: e1,
                    nodes: key.to_vec(),
                },
            ))
        } else {
            slot(2).map(|s3| {
                (
                    s3,
                    MeshError::NonManifold {
                        nodes: key.to_vec(),
                        cell: cell_of(s3),
                    },
                )
            })
        };
        match error {
            Some((at, error)) if first_error.as_ref().is_none_or(|(f, _)| at < *f) => {
                first_error = Some((at, error))
            }
            Some(_) => {}
            None => pairs.push((e1 as u32, e2 as u32)),
        }
    }
    drop(faces);
    if let Some((_, error)) = first_error {
        return Err(error);
    }

    let mut used = vec![false; nodes.len()];
    cells.iter().for_each(|&v| used[v] = true);
    if let Some(node) = used.iter().position(|u| !u) {
        return Err(MeshError::Unreferenced { node });
    }

    // Connectivity: union of the two cells of every interior face.
    let mut parent: Vec<u32> = (0..nc as u32).collect();
    fn root(parent: &mut [u32], mut i: u32) -> u32 {
        while parent[i as usize] != i {
            parent[i as usize] = parent[parent[i as usize] as usize];
            i = parent[i as usize];
        }
        i
    }
    for (a, b) in pairs {
        let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
        parent[ra.max(rb) as usize] = ra.min(rb);
    }
    let r0 = root(&mut parent, 0);
    if let Some(cell) = (1..nc as u32).find(|&e| root(&mut parent, e) != r0) {
        return Err(MeshError::Disconnected {
            cell: cell as usize,
        });
    }

    let mut facets = Vec::new();
    for slot in (0..cells.len()).filter(|&s| boundary[s]) {
        let (e, a) = (cell_of(slot), opposite(slot));
        let cell = &cells[(D + 1) * e..(D + 1) * (e + 1)];
        let mut f = [0; D];
        for (vertex, &v) in f.iter_mut().zip(
            cell.iter()
                .enumerate()
                .filter(|&(b, _)| b != a)
                .map(|(_, v)| v),
        ) {
            *vertex = v;
        }
        let (nodes_f, normal, measure) = facet_frame(&nodes, f, nodes[cell[a]]);
        facets.push(Facet {
            nodes: nodes_f,
            normal,
            measure,
            part: None,
        });
    }
    Ok(Mesh::from_parts(
        nodes,
        cells,
        facets,
        Vec::new(),
        Vec::new(),
    ))
}

/// Quality figures of a mesh, for its summary.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Figures {
    /// Shortest, mean and longest cell diameter (longest edge).
    pub min_cell_size: f64,
    pub mean_cell_size: f64,
    pub max_cell_size: f64,
    /// The shape ratio q ∈ (0, 1] (1 for the equilateral triangle or regular tetrahedron):
    /// 4√3 |T| / Σ l² in 2D, 12 (3|T|)^(2/3) / Σ l² in 3D; minimum and mean over the cells.
    pub min_quality: f64,
    pub mean_quality: f64,
}

/// Cell sizes and shape ratios of `mesh`.
pub fn figures<const D: usize>(mesh: &Mesh<D>) -> Figures {
    let mut f = Figures {
        min_cell_size: f64::INFINITY,
        mean_cell_size: 0.0,
        max_cell_size: 0.0,
        min_quality: f64::INFINITY,
        mean_quality: 0.0,
    };
    for cell in mesh.cells() {
        let p: Vec<[f64; D]> = cell.iter().map(|&v| mesh.nodes[v]).collect();
        let (mut longest, mut sum2) = (0.0f64, 0.0);
        for a in 0..=D {
            for b in a + 1..=D {
                let l2: f64 = (0..D).map(|c| (p[a][c] - p[b][c]).powi(2)).sum();
                longest = longest.max(l2.sqrt());
                sum2 += l2;
            }
        }
        let m = signed_measure(&p).abs();
        let q = if D == 2 {
            4.0 * 3f64.sqrt() * m / sum2
        } else {
            12.0 * (3.0 * m).powf(2.0 / 3.0) / sum2
        };
        f.min_cell_size = f.min_cell_size.min(longest);
        f.max_cell_size = f.max_cell_size.max(longest);
        f.mean_cell_size += longest;
        f.min_quality = f.min_quality.min(q);
        f.mean_quality += q;
    }
    f.mean_quality /= mesh.n_cells().max(1) as f64;
    f.mean_cell_size /= mesh.n_cells().max(1) as f64;
    f
}
