//! The cells around each node, and the element scatters of the time step formed as node-wise
//! gathers over them on the pool's threads.
//!
//! An element scatter out_i += Σ_{T ∋ i} c_T(i) written cell by cell writes each node from
//! every cell around it, so cells cannot simply be split over threads. Gathered node by
//! node, node i adds its cells' contributions c_T(i) in increasing T: the order in which the
//! cell-by-cell loop adds them. Chunks of nodes are independent and of a fixed length, so the
//! result is the cell-by-cell loop's bit for bit, on any number of threads, and no thread
//! holds a vector of its own.

use crate::linalg::par;
use crate::mesh::Mesh;

/// Node → the cells around it with the node's place in each: node i's entries are
/// `entries[start[i]..start[i + 1]]`, each (D + 1) e + a for cell e whose vertex a is i, in
/// increasing e. 4 (D + 1) bytes per cell and 8 per node.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeCells {
    start: Vec<usize>,
    entries: Vec<u32>,
    corners: usize,
}

impl NodeCells {
    /// The incidence of a mesh's cells, counted then filled in cell order.
    pub fn new<const D: usize>(mesh: &Mesh<D>) -> NodeCells {
        let (nn, corners) = (mesh.n_nodes(), D + 1);
        assert!(
            mesh.n_cells() * corners <= u32::MAX as usize + 1,
            "cell-node pairs fit in u32"
        );
        let mut start = vec![0usize; nn + 1];
        for &v in mesh.cells_flat() {
            start[v + 1] += 1;
        }
        for i in 0..nn {
            start[i + 1] += start[i];
        }
        let mut fill = start[..nn].to_vec();
        let mut entries = vec![0u32; start[nn]];
        for (p, &v) in mesh.cells_flat().iter().enumerate() {
            entries[fill[v]] = p as u32;
            fill[v] += 1;
        }
        NodeCells {
            start,
            entries,
            corners,
        }
    }

    /// The cells around `node` as (cell e, the node's place a among e's vertices), in
    /// increasing e.
    #[inline]
    pub fn around(&self, node: usize) -> impl Iterator<Item = (usize, usize)> + '_ {
        self.entries[self.start[node]..self.start[node + 1]]
            .iter()
            .map(|&p| (p as usize / self.corners, p as usize % self.corners))
    }

    /// The bytes it holds.
    pub fn bytes(&self) -> usize {
        8 * self.start.len() + 4 * self.entries.len()
    }

    /// out_i ← out_i + Σ_{(e, a) around i} c(e, a) for every node i, where `add(e, a, out_i)`
    /// adds cell e's contribution to its vertex a into node i's `width` entries
    /// `out[width i..width (i + 1)]` (`out` has `width` entries per node). Each node adds its
    /// cells in increasing e: the sums of the loop over cells that adds c(e, ·) to e's
    /// vertices, bit for bit, for any thread count (chunks of [`par::ROW_CHUNK`] nodes).
    pub fn gather(
        &self,
        out: &mut [f64],
        width: usize,
        add: impl Fn(usize, usize, &mut [f64]) + Sync + Send,
    ) {
        assert_eq!(out.len(), width * (self.start.len() - 1));
        par::for_each_chunk_mut(out, width * par::ROW_CHUNK, |first, chunk| {
            let first = first / width;
            for (i, out_i) in chunk.chunks_mut(width).enumerate() {
                for (e, a) in self.around(first + i) {
                    add(e, a, out_i);
                }
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::par::Threads;

    #[test]
    fn every_cell_vertex_pair_appears_once_in_cell_order() {
        let mesh = Mesh::cuboid(2.0, 1.0, 1.0, 4, 2, 3);
        let nc = NodeCells::new(&mesh);
        let mut seen = vec![false; mesh.n_cells() * 4];
        for i in 0..mesh.n_nodes() {
            let around: Vec<_> = nc.around(i).collect();
            assert!(around.windows(2).all(|w| w[0].0 < w[1].0), "node {i}");
            for (e, a) in around {
                assert_eq!(mesh.cell(e)[a], i);
                assert!(!std::mem::replace(&mut seen[4 * e + a], true));
            }
        }
        assert!(seen.iter().all(|&s| s));
        assert_eq!(nc.bytes(), 8 * (mesh.n_nodes() + 1) + 16 * mesh.n_cells());
    }

    #[test]
    fn a_gather_is_the_cell_loop_bit_for_bit_on_any_thread_count() {
        let mesh = Mesh::cuboid(1.0, 1.0, 1.0, 6, 5, 4);
        assert!(
            mesh.n_nodes() > 2 * par::ROW_CHUNK,
            "several chunks of nodes"
        );
        // Contributions of no common scale, so that another order of the sums shows.
        let c = |e: usize, a: usize, k: usize| {
            ((e * 7 + a * 3 + k) as f64).sin() * 1e3f64.powi((e % 5) as i32)
        };
        let mut serial = vec![0.5; 2 * mesh.n_nodes()];
        for (e, cell) in mesh.cells().enumerate() {
            for (a, &n) in cell.iter().enumerate() {
                for k in 0..2 {
                    serial[2 * n + k] += c(e, a, k);
                }
            }
        }
        let nc = NodeCells::new(&mesh);
        for t in [1, 2, 4] {
            let mut out = vec![0.5; 2 * mesh.n_nodes()];
            Threads::new(t).install(|| {
                nc.gather(&mut out, 2, |e, a, o| {
                    for (k, o) in o.iter_mut().enumerate() {
                        *o += c(e, a, k);
                    }
                })
            });
            assert!(
                out.iter()
                    .zip(&serial)
                    .all(|(x, y)| x.to_bits() == y.to_bits()),
                "{t} threads"
            );
        }
    }
}
