//! The mesh a run computes on, renumbered for locality of reference: its nodes in reverse
//! Cuthill–McKee order of the node graph (Cuthill & McKee, *Reducing the bandwidth of sparse
//! symmetric matrices*, ACM '69; George & Liu, *Computer Solution of Large Sparse Positive
//! Definite Systems*, 1981, §4.3: breadth first from a pseudo-peripheral node, each node's
//! unnumbered neighbours by increasing degree, the whole order reversed) and its cells sorted
//! by their lowest node; [`Numbering`] maps its fields back to the mesh as given.
//!
//! Every kernel of a step walks the mesh node by node (matrix rows, aggregation, the gathers
//! of element contributions into nodes) and reads the data of a node's neighbours and cells.
//! A mesh generator numbers nodes in the order it inserts them: the vertices of a gmsh
//! tetrahedron lie a third of the node list apart at the median, and each of those reads
//! misses the cache. Renumbered, they are a few thousand entries apart, and the steps of an
//! imported part take a quarter to a third less time (docs/src/speed/speed.md).
//!
//! Only labels change: each cell keeps its vertices in their listed order (which fixes the
//! children of its refinement, SCHEME "Refinement"), the boundary facets keep their order
//! and groups, so every result is that of the mesh as given to the solver tolerance (sums
//! are added in another order, and multigrid aggregates differ). Outputs are mapped back ([`crate::solve::stepper`]), so the user sees
//! the numbering of the file.

use super::Mesh;

/// How a renumbered mesh relates to the mesh it was made from: node i of the renumbered mesh
/// is node `node[i]` of the original, cell e is cell `cell[e]`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Numbering {
    pub node: Vec<usize>,
    pub cell: Vec<usize>,
}

impl Numbering {
    /// Per-node values (`width` per node) of the renumbered mesh in the original order.
    pub fn nodes_back<T: Copy>(&self, v: &[T], width: usize) -> Vec<T> {
        permute_back(&self.node, v, width)
    }

    /// Per-node values of the original mesh in the renumbered order.
    pub fn nodes_forward<T: Copy>(&self, v: &[T], width: usize) -> Vec<T> {
        permute_forward(&self.node, v, width)
    }

    /// Per-cell values of the renumbered mesh in the original order.
    pub fn cells_back<T: Copy>(&self, v: &[T]) -> Vec<T> {
        permute_back(&self.cell, v, 1)
    }

    /// The mesh `ordered` was made from ([`Mesh::ordered_for_locality`]), the same bits:
    /// nodes and cells back in their places and their labels back, each cell's vertices and
    /// the facets in their order. What outputs are given on, made when asked for instead
    /// of held beside the mesh a run computes on.
    pub fn mesh_back<const D: usize>(&self, ordered: &Mesh<D>) -> Mesh<D> {
        let nodes = self.nodes_back(&ordered.nodes, 1);
        let relabelled: Vec<usize> = (0..ordered.n_cells())
            .flat_map(|e| ordered.cell(e).iter().map(|&v| self.node[v]))
            .collect();
        let cells = permute_back(&self.cell, &relabelled, D + 1);
        let mut facets = ordered.facets.clone();
        for f in &mut facets {
            for v in &mut f.nodes {
                *v = self.node[*v];
            }
        }
        Mesh::from_parts(nodes, cells, facets, ordered.groups.clone(), Vec::new())
    }
}

/// out[width·to[i] + c] = v[width·i + c].
fn permute_back<T: Copy>(to: &[usize], v: &[T], width: usize) -> Vec<T> {
    assert_eq!(v.len(), width * to.len());
    let mut out = v.to_vec();
    for (i, &o) in to.iter().enumerate() {
        out[width * o..width * (o + 1)].copy_from_slice(&v[width * i..width * (i + 1)]);
    }
    out
}

/// out[width·i + c] = v[width·to[i] + c].
fn permute_forward<T: Copy>(to: &[usize], v: &[T], width: usize) -> Vec<T> {
    assert_eq!(v.len(), width * to.len());
    to.iter()
        .flat_map(|&o| v[width * o..width * (o + 1)].iter().copied())
        .collect()
}

impl<const D: usize> Mesh<D> {
    /// This mesh renumbered (see the module doc) and how it relates to this one; None for a
    /// structured mesh (its lattice numbering is local already, and its geometric levels are
    /// made for it) and for a refined one (its numbering relates it to its coarse mesh).
    pub fn ordered_for_locality(&self) -> Option<(Mesh<D>, Numbering)> {
        let (mesh, numbering) = self.clone().into_ordered_for_locality();
        numbering.map(|n| (mesh, n))
    }

    /// [`Mesh::ordered_for_locality`] in place: the mesh's own storage is permuted, so a body
    /// made from an imported mesh holds no second copy of it, nor leaves one freed in
    /// another thread's allocator arena than the run's.
    pub fn into_ordered_for_locality(mut self) -> (Mesh<D>, Option<Numbering>) {
        if !self.nesting.is_empty() || self.grid.is_some() || self.lattice.is_some() {
            return (self, None);
        }
        let node = NodeGraph::new(&self).reverse_cuthill_mckee();
        let mut new_of = vec![0; node.len()];
        for (i, &old) in node.iter().enumerate() {
            new_of[old] = i;
        }
        gather_in_place(&mut self.nodes, &node, 1);
        for v in &mut self.cells {
            *v = new_of[*v];
        }
        // Cells by lowest node, ties in cell order: a counting sort.
        let lowest = |cells: &[usize], e: usize| {
            let vertices = &cells[(D + 1) * e..(D + 1) * (e + 1)];
            *vertices.iter().min().expect("a cell has vertices")
        };
        let mut start = vec![0usize; node.len() + 1];
        for e in 0..self.n_cells() {
            start[lowest(&self.cells, e) + 1] += 1;
        }
        for v in 0..node.len() {
            start[v + 1] += start[v];
        }
        let mut cell = vec![0usize; self.n_cells()];
        for e in 0..self.n_cells() {
            let v = lowest(&self.cells, e);
            cell[start[v]] = e;
            start[v] += 1;
        }
        gather_in_place(&mut self.cells, &cell, D + 1);
        for f in &mut self.facets {
            for v in &mut f.nodes {
                *v = new_of[*v];
            }
        }
        (self, Some(Numbering { node, cell }))
    }
}

/// v[width·i + c] ← v[width·from[i] + c] for a permutation `from`, along its cycles: no copy
/// of v.
fn gather_in_place<T: Copy>(v: &mut [T], from: &[usize], width: usize) {
    assert_eq!(v.len(), width * from.len());
    let mut done = vec![false; from.len()];
    let mut first = Vec::with_capacity(width);
    for i in 0..from.len() {
        if done[i] {
            continue;
        }
        first.clear();
        first.extend_from_slice(&v[width * i..width * (i + 1)]);
        let mut j = i;
        loop {
            done[j] = true;
            let k = from[j];
            if k == i {
                v[width * j..width * (j + 1)].copy_from_slice(&first);
                break;
            }
            v.copy_within(width * k..width * (k + 1), width * j);
            j = k;
        }
    }
}

/// The graph of the mesh's edges: node i is adjacent to every other vertex of its cells;
/// the neighbours of i are `adj[xadj[i]..xadj[i + 1]]`, sorted.
struct NodeGraph {
    xadj: Vec<usize>,
    adj: Vec<u32>,
}

impl NodeGraph {
    fn new<const D: usize>(mesh: &Mesh<D>) -> NodeGraph {
        NodeGraph::of_cliques(mesh.n_nodes(), mesh.cells())
    }

    /// The graph on n nodes in which the nodes of each clique are adjacent.
    fn of_cliques<'a>(n: usize, cliques: impl Iterator<Item = &'a [usize]> + Clone) -> NodeGraph {
        let mut xadj = vec![0usize; n + 1];
        for c in cliques.clone() {
            for &v in c {
                xadj[v + 1] += c.len() - 1;
            }
        }
        for i in 0..n {
            xadj[i + 1] += xadj[i];
        }
        let mut fill = xadj[..n].to_vec();
        let mut adj = vec![0u32; xadj[n]];
        for c in cliques {
            for &v in c {
                for &u in c.iter().filter(|&&u| u != v) {
                    adj[fill[v]] = u as u32;
                    fill[v] += 1;
                }
            }
        }
        // Each row sorted and without repeats, compacted in place.
        let (mut kept, mut start) = (0, 0);
        for i in 0..n {
            let end = xadj[i + 1];
            adj[start..end].sort_unstable();
            let first = kept;
            for q in start..end {
                if q == start || adj[q] != adj[q - 1] {
                    adj[kept] = adj[q];
                    kept += 1;
                }
            }
            xadj[i] = first;
            start = end;
        }
        xadj[n] = kept;
        adj.truncate(kept);
        NodeGraph { xadj, adj }
    }

    fn n(&self) -> usize {
        self.xadj.len() - 1
    }

    fn neighbours(&self, v: usize) -> impl Iterator<Item = usize> + '_ {
        self.adj[self.xadj[v]..self.xadj[v + 1]]
            .iter()
            .map(|&u| u as usize)
    }

    fn degree(&self, v: usize) -> usize {
        self.xadj[v + 1] - self.xadj[v]
    }

    /// Cuthill–McKee from `start` over its component: appends the component's nodes to
    /// `order` breadth first, each node's unnumbered neighbours by increasing (degree, index),
    /// and marks them in `numbered`. Returns the number of breadth-first levels and the index
    /// in `order` where the last one starts. `numbered` is restored when `keep` is false (a
    /// trial from a candidate start).
    fn sweep(
        &self,
        start: usize,
        order: &mut Vec<usize>,
        numbered: &mut [bool],
        keep: bool,
    ) -> (usize, usize) {
        let first = order.len();
        numbered[start] = true;
        order.push(start);
        let (mut head, mut level_end, mut last_level, mut levels) = (first, first + 1, first, 1);
        let mut next = Vec::new();
        while head < order.len() {
            if head == level_end {
                (last_level, level_end, levels) = (head, order.len(), levels + 1);
            }
            let v = order[head];
            head += 1;
            next.clear();
            next.extend(self.neighbours(v).filter(|&u| !numbered[u]));
            next.sort_unstable_by_key(|&u| (self.degree(u), u));
            for &u in &next {
                numbered[u] = true;
                order.push(u);
            }
        }
        if !keep {
            for &v in &order[first..] {
                numbered[v] = false;
            }
        }
        (levels, last_level)
    }

    /// The reverse Cuthill–McKee order: `order[i]` is the node numbered i. Each component
    /// starts from a pseudo-peripheral node: from its lowest node, repeatedly the node of least
    /// degree in the last breadth-first level, while the number of levels grows.
    fn reverse_cuthill_mckee(&self) -> Vec<usize> {
        let n = self.n();
        let mut order = Vec::with_capacity(n);
        let mut numbered = vec![false; n];
        let mut trial = Vec::new();
        for first in 0..n {
            if numbered[first] {
                continue;
            }
            let (mut start, mut depth) = (first, 0);
            loop {
                trial.clear();
                let (levels, last) = self.sweep(start, &mut trial, &mut numbered, false);
                if levels <= depth {
                    break;
                }
                depth = levels;
                let far = trial[last..]
                    .iter()
                    .copied()
                    .min_by_key(|&v| (self.degree(v), v));
                match far {
                    Some(v) if v != start => start = v,
                    _ => break,
                }
            }
            self.sweep(start, &mut order, &mut numbered, true);
        }
        order.reverse();
        order
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::signed_measure;

    /// A box mesh with its nodes and cells scrambled, as an unstructured file lists them.
    fn scrambled_box() -> Mesh<3> {
        let b = Mesh::cuboid(2.0, 1.0, 1.0, 6, 3, 4);
        let n = b.n_nodes();
        // Permutations: 104729 and 7919 are primes that divide neither count.
        let label = |v: usize| (v * 104_729) % n;
        let mut nodes = vec![[0.0; 3]; n];
        for (v, p) in b.nodes.iter().enumerate() {
            nodes[label(v)] = *p;
        }
        let nc = b.n_cells();
        let cells = (0..nc)
            .flat_map(|e| b.cell((e * 7_919) % nc).iter().map(|&v| label(v)))
            .collect();
        Mesh::from_cells(nodes, cells).unwrap()
    }

    /// The largest distance between two vertices of a cell.
    fn spread<const D: usize>(m: &Mesh<D>) -> usize {
        m.cells()
            .map(|c| c.iter().max().unwrap() - c.iter().min().unwrap())
            .max()
            .unwrap()
    }

    #[test]
    fn the_same_cells_and_facets_under_new_labels_with_a_small_spread() {
        let m = scrambled_box();
        let (o, numbering) = m.ordered_for_locality().unwrap();
        assert_eq!((o.n_nodes(), o.n_cells()), (m.n_nodes(), m.n_cells()));
        // Node i is the original's node[i]; cell e is the original's cell[e] with its
        // vertices relabelled in their order (so the same signed measure and children).
        for (i, &old) in numbering.node.iter().enumerate() {
            assert_eq!(o.nodes[i], m.nodes[old]);
        }
        for (e, &old) in numbering.cell.iter().enumerate() {
            let points = |mesh: &Mesh<3>, c: &[usize]| -> Vec<[f64; 3]> {
                c.iter().map(|&v| mesh.nodes[v]).collect()
            };
            let (a, b) = (points(&o, o.cell(e)), points(&m, m.cell(old)));
            assert_eq!(a, b);
            assert_eq!(signed_measure(&a), signed_measure(&b));
        }
        let mut cells = numbering.cell.clone();
        cells.sort_unstable();
        assert_eq!(cells, (0..m.n_cells()).collect::<Vec<_>>(), "a permutation");
        // Facets keep their order, normals, measures and parts.
        for (f, g) in m.facets.iter().zip(&o.facets) {
            assert_eq!((f.normal, f.measure, f.part), (g.normal, g.measure, g.part));
            for (&u, &v) in f.nodes.iter().zip(&g.nodes) {
                assert_eq!(m.nodes[u], o.nodes[v]);
            }
        }
        // Cells sorted by their lowest node; a cell's nodes close in the new order: the
        // lattice numbering's spread is a layer and a row, 7·4 + 4 + 1 = 33 here, the
        // scramble's most of the 140 nodes.
        let lowest: Vec<usize> = o.cells().map(|c| *c.iter().min().unwrap()).collect();
        assert!(lowest.windows(2).all(|w| w[0] <= w[1]));
        let (before, after) = (spread(&m), spread(&o));
        assert!(before > 100 && after <= 40, "spread {before} -> {after}");
        // The mesh alone fixes the order.
        assert_eq!(m.ordered_for_locality().unwrap().1, numbering);
    }

    #[test]
    fn fields_map_back_and_forth() {
        let (_, numbering) = scrambled_box().ordered_for_locality().unwrap();
        let n = numbering.node.len();
        let v: Vec<f64> = (0..3 * n).map(|i| i as f64).collect();
        let back = numbering.nodes_back(&v, 3);
        assert_eq!(numbering.nodes_forward(&back, 3), v);
        // Value c of renumbered node i lands at original node node[i].
        let i = n / 3;
        assert_eq!(back[3 * numbering.node[i] + 2], v[3 * i + 2]);
        let c: Vec<usize> = (0..numbering.cell.len()).collect();
        let cb = numbering.cells_back(&c);
        for (e, &old) in numbering.cell.iter().enumerate() {
            assert_eq!(cb[old], e);
        }
    }

    /// An imported part (its facets in physical groups) and the scrambled box come back from
    /// their renumbered copies bit for bit: what outputs are given on.
    #[test]
    fn the_mesh_as_given_comes_back_bit_for_bit() {
        let cylinder: Mesh<3> =
            crate::mesh::import::import(include_bytes!("../../tests/meshes/cylinder.msh")).unwrap();
        assert!(!cylinder.groups.is_empty());
        for given in [cylinder, scrambled_box()] {
            let (ordered, numbering) = given.ordered_for_locality().unwrap();
            assert_ne!(ordered.nodes, given.nodes);
            let back = numbering.mesh_back(&ordered);
            let cells = |m: &Mesh<3>| -> Vec<usize> {
                (0..m.n_cells()).flat_map(|e| m.cell(e).to_vec()).collect()
            };
            assert_eq!(back.nodes, given.nodes);
            assert_eq!(cells(&back), cells(&given));
            assert_eq!(back.facets, given.facets);
            assert_eq!(back.groups, given.groups);
            assert!(back.nesting.is_empty() && back.grid.is_none() && back.lattice.is_none());
        }
    }

    /// The graph of the undirected `edges` on n vertices.
    fn graph(n: usize, edges: &[(usize, usize)]) -> NodeGraph {
        let flat: Vec<usize> = edges.iter().flat_map(|&(a, b)| [a, b]).collect();
        NodeGraph::of_cliques(n, flat.chunks_exact(2))
    }

    #[test]
    fn a_scrambled_grid_comes_back_to_its_natural_bandwidth() {
        let (nx, ny) = (40, 25);
        let n = nx * ny;
        // A permutation: 7919 is prime to n.
        let label = |i: usize, j: usize| ((j * nx + i) * 7919) % n;
        let mut edges = Vec::new();
        for j in 0..ny {
            for i in 0..nx {
                if i + 1 < nx {
                    edges.push((label(i, j), label(i + 1, j)));
                }
                if j + 1 < ny {
                    edges.push((label(i, j), label(i, j + 1)));
                }
            }
        }
        let g = graph(n, &edges);
        let order = g.reverse_cuthill_mckee();
        let mut at = vec![usize::MAX; n];
        for (i, &v) in order.iter().enumerate() {
            assert_eq!(at[v], usize::MAX, "vertex {v} twice");
            at[v] = i;
        }
        let bandwidth = |at: &dyn Fn(usize) -> usize| {
            edges
                .iter()
                .map(|&(a, b)| at(a).abs_diff(at(b)))
                .max()
                .unwrap()
        };
        assert!(bandwidth(&|v| v) > n / 2);
        // Breadth first from a corner numbers the grid by anti-diagonals: the bandwidth is at
        // most the longest one's length plus one.
        let b = bandwidth(&|v| at[v]);
        assert!(b <= nx.min(ny) + 1, "bandwidth {b}");
    }

    #[test]
    fn every_component_is_ordered_in_one_piece() {
        // Two paths, 0-2-4 and 1-3, and an isolated vertex 5.
        let g = graph(6, &[(0, 2), (2, 4), (1, 3)]);
        let order = g.reverse_cuthill_mckee();
        let mut sorted = order.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..6).collect::<Vec<_>>());
        let at = |v: usize| order.iter().position(|&u| u == v).unwrap();
        assert_eq!(at(0).abs_diff(at(2)), 1);
        assert_eq!(at(2).abs_diff(at(4)), 1);
        assert_eq!(at(1).abs_diff(at(3)), 1);
    }

    #[test]
    fn structured_and_refined_meshes_keep_their_numbering() {
        assert!(Mesh::cuboid(1.0, 1.0, 1.0, 2, 2, 2)
            .ordered_for_locality()
            .is_none());
        assert!(scrambled_box().refine().ordered_for_locality().is_none());
    }
}
