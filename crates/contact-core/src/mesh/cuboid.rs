//! The structured box [0, lx] × [0, ly] × [0, lz] (docs/src/explanation/numerics.md#meshes, SCHEME "General
//! meshes and 3D" (b)): a lattice of nx × ny × nz cuboid cells, each cut into the 6 tetrahedra
//! of the Kuhn (Freudenthal) split, so that boxes of h and h/2 are nested.
//!
//! Numbering (what [`crate::fem::prolongation`] and the rotated test mesh rely on):
//! - node(i, j, k) = i + (nx + 1)·(j + (ny + 1)·k) at (i·lx/nx, j·ly/ny, k·lz/nz), x fastest;
//! - cube cell (i, j, k) in the same order (x fastest), its 6 tetrahedra consecutive: cells
//!   6·(i + nx·(j + ny·k)) + p for p = 0..6;
//! - tetrahedron p is the monotone lattice path v000 → v111 that steps along the axes in the
//!   order [`KUHN_PATHS`]`[p]`: vertices (v000, v000 + e_a, v000 + e_a + e_b, v111) for the
//!   path (a, b, c). The even permutations (p = 0, 3, 4) are right-handed as they stand; the
//!   odd ones (p = 1, 2, 5) have their vertices 1 and 2 swapped, so that every cell has the
//!   orientation of the first, as [`Mesh`] requires (vertex 0 stays the cell's lowest corner
//!   and vertex 3 its highest).

use super::{facet_frame, Facet, Lattice, Mesh};

/// The axis order of the 6 Kuhn paths of a cube cell, in the order of the cells: the
/// permutations of (x, y, z) = (0, 1, 2) in lexicographic order.
pub const KUHN_PATHS: [[usize; 3]; 6] = [
    [0, 1, 2],
    [0, 2, 1],
    [1, 0, 2],
    [1, 2, 0],
    [2, 0, 1],
    [2, 1, 0],
];

/// Whether Kuhn path p is an odd permutation (its vertices 1 and 2 are swapped in the cell).
pub const fn kuhn_path_is_odd(p: usize) -> bool {
    matches!(p, 1 | 2 | 5)
}

/// The index p in [`KUHN_PATHS`] of the path that steps along the axes in the order
/// (a, b, c), a permutation of (0, 1, 2).
pub fn kuhn_path_index(order: [usize; 3]) -> usize {
    // Lexicographic rank of a permutation of three: 2 per first axis, then 1 if the last two
    // are descending.
    2 * order[0] + usize::from(order[1] > order[2])
}

impl Mesh<3> {
    /// The Kuhn box of nx × ny × nz cuboid cells of [0, lx] × [0, ly] × [0, lz] (see the
    /// module doc for the node, cell and vertex order): (nx+1)(ny+1)(nz+1) nodes and
    /// 6·nx·ny·nz tetrahedra, all right-handed (positive signed volume); the boundary facets
    /// are those [`Mesh::from_cells`] finds, in its order (4·(nx·ny + ny·nz + nz·nx)
    /// triangles, outward normals), untagged; [`Mesh::lattice`] records the lattice so that nested boxes
    /// prolongate exactly.
    ///
    /// Panics if a count is 0 or a length is not positive and finite.
    pub fn cuboid(lx: f64, ly: f64, lz: f64, nx: usize, ny: usize, nz: usize) -> Mesh<3> {
        let size = [lx, ly, lz];
        let n = [nx, ny, nz];
        assert!(
            n.iter().all(|&c| c >= 1),
            "a box needs at least one cell per axis"
        );
        assert!(
            size.iter().all(|&l| l.is_finite() && l > 0.0),
            "a box needs positive finite lengths"
        );
        let node = |i: usize, j: usize, k: usize| i + (nx + 1) * (j + (ny + 1) * k);
        let mut nodes = Vec::with_capacity((nx + 1) * (ny + 1) * (nz + 1));
        for k in 0..=nz {
            for j in 0..=ny {
                for i in 0..=nx {
                    // i·lx/nx from the integer index (not accumulated), so the nodes of the
                    // boxes of h and h/2 that coincide are bit-identical.
                    nodes.push([
                        i as f64 * lx / nx as f64,
                        j as f64 * ly / ny as f64,
                        k as f64 * lz / nz as f64,
                    ]);
                }
            }
        }
        // Node-index offsets of the unit steps along x, y and z.
        let step = [1, nx + 1, (nx + 1) * (ny + 1)];
        let mut cells = Vec::with_capacity(24 * nx * ny * nz);
        let mut facets = Vec::with_capacity(4 * (nx * ny + ny * nz + nz * nx));
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    let base = [i, j, k];
                    let v000 = node(i, j, k);
                    let on_boundary = (0..3).any(|a| base[a] == 0 || base[a] + 1 == n[a]);
                    for (p, &[a, b, _]) in KUHN_PATHS.iter().enumerate() {
                        // The vertices and their offsets in the cube (0 or 1 per axis).
                        let mut off = [[0; 3], [0; 3], [0; 3], [1; 3]];
                        off[1][a] = 1;
                        off[2] = off[1];
                        off[2][b] = 1;
                        if kuhn_path_is_odd(p) {
                            off.swap(1, 2);
                        }
                        let cell =
                            off.map(|o| v000 + o[0] * step[0] + o[1] * step[1] + o[2] * step[2]);
                        cells.extend_from_slice(&cell);
                        if on_boundary {
                            boundary_faces(&nodes, &cell, &off, base, n, &mut facets);
                        }
                    }
                }
            }
        }
        // The facets are those quality::build finds, in its order (a test compares them); made
        // here directly because the box needs none of its checks, and its face map dominates
        // for large boxes (393,216 cells: 1 s against 0.02 s here).
        let mut mesh = Mesh::from_parts(nodes, cells, facets, Vec::new(), Vec::new());
        mesh.lattice = Some(Lattice { size, cells: n });
        mesh
    }
}

/// Appends the faces of one cell that lie on the box's boundary, as [`super::quality::build`]
/// finds boundary facets: the face opposite vertex 3, 2, 1, 0 in turn, its vertices in the
/// cell's order, then oriented outward by [`facet_frame`]. `off` holds the cell's vertices'
/// offsets in their cube (0 or 1 per axis), `base` the cube's lattice index, `n` the counts.
fn boundary_faces(
    nodes: &[[f64; 3]],
    cell: &[usize; 4],
    off: &[[usize; 3]; 4],
    base: [usize; 3],
    n: [usize; 3],
    facets: &mut Vec<Facet<3>>,
) {
    for a in (0..4).rev() {
        let rest: [usize; 3] = std::array::from_fn(|q| if q < a { q } else { q + 1 });
        // On a box face: all three vertices on the cube's low side of an axis where the cube
        // is the first, or on its high side where it is the last.
        let outside = (0..3).any(|axis| {
            (base[axis] == 0 && rest.iter().all(|&q| off[q][axis] == 0))
                || (base[axis] + 1 == n[axis] && rest.iter().all(|&q| off[q][axis] == 1))
        });
        if outside {
            let (f, normal, measure) = facet_frame(nodes, rest.map(|q| cell[q]), nodes[cell[a]]);
            facets.push(Facet {
                nodes: f,
                normal,
                measure,
                part: None,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::signed_measure;

    #[test]
    fn paths_are_ranked_in_order_and_signed_as_documented() {
        for (p, order) in KUHN_PATHS.iter().enumerate() {
            assert_eq!(kuhn_path_index(*order), p);
            // The sign of a permutation of three: +1 for cyclic shifts of (0, 1, 2).
            let even = [[0, 1, 2], [1, 2, 0], [2, 0, 1]].contains(order);
            assert_eq!(kuhn_path_is_odd(p), !even, "path {p}");
        }
    }

    #[test]
    fn the_mesh_is_the_one_the_general_constructor_makes_of_its_cells() {
        for (l, n) in [
            ([1.0, 1.0, 1.0], [1, 1, 1]),
            ([0.3, 2.0, 1.1], [3, 2, 4]),
            ([2.0, 1.0, 1.0], [8, 4, 4]),
            ([1.0, 1.0, 1.0], [1, 5, 1]),
        ] {
            let m = Mesh::<3>::cuboid(l[0], l[1], l[2], n[0], n[1], n[2]);
            let g = Mesh::<3>::from_cells(m.nodes.clone(), m.cells.clone()).unwrap();
            assert_eq!(m.nodes, g.nodes);
            assert_eq!(m.cells, g.cells);
            assert_eq!(m.facets, g.facets, "{n:?}");
            assert!(m.nesting.is_empty() && m.groups.is_empty() && m.grid.is_none());
        }
    }

    #[test]
    fn one_cube_is_six_right_handed_paths_round_its_diagonal() {
        let m = Mesh::<3>::cuboid(1.0, 2.0, 3.0, 1, 1, 1);
        assert_eq!((m.n_nodes(), m.n_cells(), m.facets.len()), (8, 6, 12));
        for (p, cell) in m.cells().enumerate() {
            let x: Vec<[f64; 3]> = cell.iter().map(|&v| m.nodes[v]).collect();
            assert!((signed_measure(&x) - 1.0).abs() < 1e-15, "cell {p}");
            assert_eq!((cell[0], cell[3]), (0, 7));
            // The first step of the path is along KUHN_PATHS[p][0].
            let first = if kuhn_path_is_odd(p) {
                cell[2]
            } else {
                cell[1]
            };
            assert_eq!(first, [1, 2, 4][KUHN_PATHS[p][0]]);
        }
        assert_eq!(
            m.lattice,
            Some(Lattice {
                size: [1.0, 2.0, 3.0],
                cells: [1, 1, 1]
            })
        );
    }
}
