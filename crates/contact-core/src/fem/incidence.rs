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

    /// out_i ← out_i + Σ_{(e, a) around i} c(e, a) for every node i, where
    /// `add(e, &value(e), a, out_i)` adds cell e's contribution to its vertex a into node i's
    /// `width` entries `out[width i..width (i + 1)]` (`out` has `width` entries per node).
    /// Each node adds its cells in increasing e: the sums of the loop over cells that adds
    /// c(e, ·) to e's vertices, bit for bit, for any thread count, as `value` is a function
    /// of e alone. `value(e)` is formed once for each chunk of [`CELL_VALUE_CHUNK`] nodes
    /// that has cell e around it and is held only while that chunk is gathered, instead of
    /// once per cell into a field the size of the mesh; a thread reuses one buffer for the
    /// chunks it takes (a chunk's values fill megabytes, which the allocator would map and
    /// fault in afresh for every chunk). A chunk
    /// holds the values of the cells between its nodes' lowest and highest cell; on a mesh
    /// numbered for locality (cells by lowest node, [`crate::mesh`]) those are about the
    /// chunk's own cells, and the cells a chunk shares with the next are formed twice.
    pub fn gather_cell_values<V: Send>(
        &self,
        out: &mut [f64],
        width: usize,
        value: impl Fn(usize) -> V + Sync + Send,
        add: impl Fn(usize, &V, usize, &mut [f64]) + Sync + Send,
    ) {
        assert_eq!(out.len(), width * (self.start.len() - 1));
        let chunk = width * CELL_VALUE_CHUNK;
        let held = Vec::<Option<V>>::new;
        par::for_each_chunk_mut_with(out, chunk, held, |values, first, part| {
            let nodes = first / width..first / width + part.len() / width;
            let cells = |i: usize| &self.entries[self.start[i]..self.start[i + 1]];
            let lowest = nodes.clone().filter_map(|i| cells(i).first()).min();
            let highest = nodes.clone().filter_map(|i| cells(i).last()).max();
            let (Some(&lowest), Some(&highest)) = (lowest, highest) else {
                return;
            };
            let first_cell = lowest as usize / self.corners;
            values.clear();
            values.resize_with(highest as usize / self.corners + 1 - first_cell, || None);
            for (i, out_i) in nodes.zip(part.chunks_mut(width)) {
                for (e, a) in self.around(i) {
                    let v = values[e - first_cell].get_or_insert_with(|| value(e));
                    add(e, v, a, out_i);
                }
            }
        });
    }
}

/// Nodes whose cells' values [`NodeCells::gather_cell_values`] holds at a time. The part of
/// `benches/part` (82k nodes, 442k cells) and box-exp3 at 1/32 (71k nodes, 393k cells)
/// form 1.36 and 1.53 values a cell with it and hold at most 34k and 36k; with 16 × 1024
/// nodes, 1.08 and 1.13 values a cell, and up to 107k held.
const CELL_VALUE_CHUNK: usize = 4 * par::ROW_CHUNK;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::par::Threads;

    fn same_bits(a: &[f64], b: &[f64]) -> bool {
        a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
    }

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

    /// Cell values formed per chunk of nodes give the cell loop's sums bit for bit, on a box
    /// numbered for locality and on the same box scrambled (a chunk's cells then span most
    /// of the mesh), and each chunk forms the value of each cell around its nodes once.
    #[test]
    fn a_gather_of_cell_values_is_the_cell_loop_bit_for_bit() {
        let boxed = Mesh::cuboid(1.0, 1.0, 1.0, 7, 6, 5);
        // Nodes and cells relabelled by primes that divide neither count.
        let (n, nc) = (boxed.n_nodes(), boxed.n_cells());
        let label = |v: usize| (v * 104_729) % n;
        let mut nodes = vec![[0.0; 3]; n];
        for (v, p) in boxed.nodes.iter().enumerate() {
            nodes[label(v)] = *p;
        }
        let cells = (0..nc)
            .flat_map(|e| boxed.cell((e * 7_919) % nc).iter().map(|&v| label(v)))
            .collect();
        let scrambled = Mesh::from_cells(nodes, cells).unwrap();
        for mesh in [boxed, scrambled] {
            assert!(
                mesh.n_nodes() > 2 * CELL_VALUE_CHUNK,
                "several chunks of nodes"
            );
            let value = |e: usize| {
                let s = (e as f64).sin() * 1e3f64.powi((e % 5) as i32);
                [s, (e as f64 * 0.7).cos()]
            };
            let c = |v: &[f64; 2], a: usize, k: usize| v[k] * (1.0 + a as f64) / 3.0;
            let mut serial = vec![0.5; 2 * mesh.n_nodes()];
            for (e, cell) in mesh.cells().enumerate() {
                for (a, &n) in cell.iter().enumerate() {
                    for k in 0..2 {
                        serial[2 * n + k] += c(&value(e), a, k);
                    }
                }
            }
            let nc = NodeCells::new(&mesh);
            for t in [1, 2, 4] {
                let formed = std::sync::atomic::AtomicUsize::new(0);
                let mut out = vec![0.5; 2 * mesh.n_nodes()];
                Threads::new(t).install(|| {
                    nc.gather_cell_values(
                        &mut out,
                        2,
                        |e| {
                            formed.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                            value(e)
                        },
                        |_, v, a, o| {
                            for (k, o) in o.iter_mut().enumerate() {
                                *o += c(v, a, k);
                            }
                        },
                    )
                });
                assert!(same_bits(&out, &serial), "{t} threads");
                // Once per chunk and cell around the chunk's nodes, no more.
                let once_per_chunk: usize = (0..mesh.n_nodes())
                    .step_by(CELL_VALUE_CHUNK)
                    .map(|first| {
                        let last = (first + CELL_VALUE_CHUNK).min(mesh.n_nodes());
                        let mut around: Vec<usize> = (first..last)
                            .flat_map(|i| nc.around(i).map(|(e, _)| e))
                            .collect();
                        around.sort_unstable();
                        around.dedup();
                        around.len()
                    })
                    .sum();
                assert!(once_per_chunk > mesh.n_cells(), "chunks that share cells");
                assert_eq!(formed.into_inner(), once_per_chunk, "{t} threads");
            }
        }
    }
}
