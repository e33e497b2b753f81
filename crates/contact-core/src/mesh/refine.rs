//! Uniform (red) refinement (docs/src/explanation/numerics.md#meshes), nested by construction: every cell
//! is cut into 2^D children through its edge midpoints, in SCHEME's child order.
//!
//! - Triangles (x0, x1, x2), mij the midpoint of edge ij: (x0, m01, m02), (m01, x1, m12),
//!   (m02, m12, x2), (m01, m12, m02).
//! - Tetrahedra: Bey's regular refinement (J. Bey, Computing 55 (1995) 355–378), the
//!   octahedron cut along x02–x13: (x0,x01,x02,x03), (x01,x1,x12,x13), (x02,x12,x2,x23),
//!   (x03,x13,x23,x3), (x01,x02,x03,x13), (x01,x02,x12,x13), (x02,x03,x13,x23),
//!   (x02,x12,x13,x23).
//!
//! Numbering: the coarse nodes keep their indices; a new node is added for each coarse edge
//! at its first appearance (cells in order, edges (0,1), (0,2), (0,3), (1,2), (1,3), (2,3) of
//! the cell in that order); children of cell c are cells 2^D·c + k. Boundary facets split
//! the same way (children 2^(D−1)·f + k) and keep their parent's part, group and normal: new
//! nodes stay on the chords of curved boundaries.

#![allow(clippy::needless_range_loop)] // Index loops over vertices and components spell out the formulas.

use super::quality::IndexMap;
use super::{Facet, Mesh, Nesting};

/// The local edges of a simplex, in numbering order.
fn local_edges(d: usize) -> &'static [[usize; 2]] {
    if d == 2 {
        &[[0, 1], [0, 2], [1, 2]]
    } else {
        &[[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]
    }
}

/// Children of a cell, as indices into (x0.., then the edge midpoints in `local_edges` order).
fn children(d: usize) -> &'static [&'static [usize]] {
    if d == 2 {
        // x0 x1 x2 m01 m02 m12
        &[&[0, 3, 4], &[3, 1, 5], &[4, 5, 2], &[3, 5, 4]]
    } else {
        // x0 x1 x2 x3 m01 m02 m03 m12 m13 m23
        &[
            &[0, 4, 5, 6],
            &[4, 1, 7, 8],
            &[5, 7, 2, 9],
            &[6, 8, 9, 3],
            &[4, 5, 6, 8],
            &[4, 5, 7, 8],
            &[5, 6, 8, 9],
            &[5, 7, 8, 9],
        ]
    }
}

/// One red refinement of `coarse`.
pub fn red<const D: usize>(coarse: &Mesh<D>) -> Mesh<D> {
    let n0 = coarse.n_nodes();
    let mut nodes = coarse.nodes.clone();
    let mut midpoints: Vec<[usize; 2]> = Vec::new();
    let mut index: IndexMap<[usize; 2], usize> =
        IndexMap::with_capacity_and_hasher(coarse.n_cells() * 2, Default::default());
    let mut mid = |a: usize, b: usize, nodes: &mut Vec<[f64; D]>| -> usize {
        let key = [a.min(b), a.max(b)];
        *index.entry(key).or_insert_with(|| {
            let (p, q) = (nodes[a], nodes[b]);
            nodes.push(std::array::from_fn(|c| 0.5 * (p[c] + q[c])));
            midpoints.push(key);
            nodes.len() - 1
        })
    };
    let edges = local_edges(D);
    let kids = children(D);
    let mut cells = Vec::with_capacity(coarse.n_cells() * kids.len() * (D + 1));
    let mut local = Vec::with_capacity(D + 1 + edges.len());
    for cell in coarse.cells() {
        local.clear();
        local.extend_from_slice(cell);
        for &[a, b] in edges {
            local.push(mid(cell[a], cell[b], &mut nodes));
        }
        for child in kids {
            cells.extend(child.iter().map(|&k| local[k]));
        }
    }
    let mut facets = Vec::with_capacity(coarse.facets.len() << (D - 1));
    for f in &coarse.facets {
        let split = |nodes: [usize; D]| Facet {
            nodes,
            measure: f.measure / (1 << (D - 1)) as f64,
            ..*f
        };
        let v = f.nodes;
        if D == 2 {
            let m = mid(v[0], v[1], &mut nodes);
            facets.push(split(std::array::from_fn(|c| [v[0], m][c])));
            facets.push(split(std::array::from_fn(|c| [m, v[1]][c])));
        } else {
            let (m01, m02, m12) = (
                mid(v[0], v[1], &mut nodes),
                mid(v[0], v[2], &mut nodes),
                mid(v[1], v[2], &mut nodes),
            );
            for t in [
                [v[0], m01, m02],
                [m01, v[1], m12],
                [m02, m12, v[2]],
                [m01, m12, m02],
            ] {
                facets.push(split(std::array::from_fn(|c| t[c])));
            }
        }
    }
    let per = 1usize << (D - 1);
    let groups = coarse
        .groups
        .iter()
        .map(|g| g.refined(|f| per * f..per * (f + 1)))
        .collect();
    let mut nesting = coarse.nesting.clone();
    nesting.push(Nesting {
        coarse_nodes: n0,
        midpoints,
    });
    Mesh::from_parts(nodes, cells, facets, groups, nesting)
}
