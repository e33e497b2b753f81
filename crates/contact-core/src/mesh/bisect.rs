//! Local refinement by bisection (issue 38, part 2): the cells a caller marks are bisected,
//! and as many others as it takes to leave no hanging node, so that refinement can follow
//! an error estimate instead of halving h everywhere as [`super::refine`] does.
//!
//! Every cell carries its refinement data beside the mesh ([`Bisection`]); a bisection cuts
//! a cell through the midpoint z of its refinement edge x0–x1 into two children.
//!
//! - **2D: newest-vertex bisection** (W. F. Mitchell, ACM TOMS 15 (1989) 326–347; P. Binev,
//!   W. Dahmen, R. DeVore, Numer. Math. 97 (2004) 219–268; R. Stevenson, Math. Comp. 77
//!   (2008) 227–241). A triangle (x0, x1, x2) with refinement edge x0–x1 has the children
//!   (x2, x0, z) and (x1, x2, z): each child's refinement edge is the edge opposite its
//!   newest vertex z, so the grandchildren of a triangle are cut through the midpoints of
//!   its other two edges and a triangle's descendants fall into at most four similarity
//!   classes (the minimum angle stays bounded below by the initial mesh's alone).
//!   The initial refinement edge is the longest edge.
//! - **3D: the marked tetrahedra of Arnold, Mukherjee & Pouly** (D. N. Arnold, A. Mukherjee,
//!   L. Pouly, SIAM J. Sci. Comput. 22 (2000) 431–448). A tetrahedron has a refinement edge
//!   x0–x1, a marked edge on each face (the refinement edge on the two faces that hold it)
//!   and a flag. It is *planar* (type P) when the marked edges of the faces opposite x0 and
//!   x1 meet at one vertex xk (all marked edges in the plane x0 x1 xk), otherwise of type A,
//!   M or O. Its children (xi, x2, x3, z) take as refinement edge the marked edge of the face
//!   they inherit (xi x2 x3); a cut face xi xj z is marked at xi–xj (newest-vertex bisection
//!   of the parent's face, which was marked at x0–x1); the new face x2 x3 z is marked at
//!   x2–x3, except in a flagged planar parent, where it is marked at z–xk; the children of
//!   an unflagged planar parent are flagged. The children of a tetrahedron of type A, M or
//!   O are then unflagged planar (Pu), those of a Pu flagged planar (Pf) and those of a Pf
//!   of type A: after the first bisection the types cycle Pu → Pf → A → Pu (checked by the
//!   tests), a period of three bisections as in the algorithms
//!   of Maubach (J. M. Maubach, SIAM J. Sci. Comput. 16 (1995) 210–227) and Kossaczký
//!   (J. Comput. Appl. Math. 55 (1994) 275–288). AMP prove that the descendants of one
//!   tetrahedron then fall into finitely many similarity classes: shape regularity is
//!   bounded by the initial mesh alone, however often and wherever a mesh is refined.
//!   The initial marking is AMP's, which needs no special vertex order and so works on any
//!   conforming tetrahedral mesh (generated, imported): the edges of the mesh are ordered
//!   strictly (longer first), and each tetrahedron's refinement edge and each face's marked
//!   edge is its greatest edge in that order; no flag is set. Since a face's marked edge is
//!   a property of the face alone, the two tetrahedra of a face agree on it, and a face is
//!   always first cut at its marked edge, by whichever of its tetrahedra is bisected first.
//!
//! The global edge order (2D and 3D): longer edges first, equal lengths by the lower
//! sorted node index pair first. The squared length of an edge is computed from its
//! lower-indexed node wherever the edge appears, so that the cells of an edge agree on its
//! place and the order is strict and deterministic (rounding may break a tie of exactly
//! equal lengths either way, but the same way everywhere).
//!
//! **Closure.** After the marked cells are bisected (each once), every cell that has a node
//! in the interior of one of its edges (a hanging node: the midpoint of an edge bisected in
//! this step) is bisected, in sweeps over the cells in order, until no hanging node remains.
//! In 2D this gives the same mesh as the recursive bisection of the neighbour across the
//! refinement edge (Stevenson's compatible bisection): both make the smallest conforming
//! mesh of the bisection forest that refines the marked cells, which is unique. In 3D it is
//! AMP's refinement loop, which they prove terminates for their initial marking.
//!
//! **Invariants of the result** ([`Step`]):
//! - conforming: every interior facet shared by two cells, no hanging node;
//! - nested: old nodes keep their indices and new nodes are appended, each the midpoint of
//!   an edge of two earlier nodes ([`Step::midpoints`], in order, so P1 interpolation from the
//!   previous mesh is node value = mean of the endpoints applied in order), and every new
//!   cell lies in the cell of the previous mesh given by [`Step::parent`]. The bisection
//!   forest of a cell does not depend on how it was reached, so every node of an adaptive
//!   mesh whose cells have at most g bisections is a node of the mesh with every cell
//!   bisected g times;
//! - cells the step does not touch keep their vertex order; a new cell has the orientation
//!   (sign of its measure) of the previous cell it lies in;
//! - a bisected boundary facet is split the same way as its cell's face (at the facet's
//!   marked edge in 3D), into facets that keep its part, its group and its outward normal
//!   (the normal of the parent: flat facets stay flat, and on a curved part the new nodes lie
//!   on the chords, as in the red refinement); measures are recomputed from the coordinates;
//!   the facets of one old facet are consecutive, in the old facet order;
//! - the new cells of one old cell are consecutive, in the old cell order, so `parent` is
//!   non-decreasing;
//! - deterministic: the result depends on the mesh and the set of marked cells only.
//!
//! A bisected mesh is neither a structured grid nor a red refinement, so its
//! [`Mesh::grid`] and [`Mesh::lattice`] are None and its [`Mesh::nesting`] is empty: the
//! multigrid levels built from `nesting` assume that its last entry accounts for every
//! node of the mesh, which a red refinement followed by bisections no longer satisfies. The
//! relation between a bisected mesh and the previous one is described by its [`Step`]; an
//! adaptive study (`crate::study::adapt`) composes the steps of several cycles into levels
//! of `nesting` (midpoints whose ends may be earlier midpoints) for its runs' multigrid.

#![allow(clippy::needless_range_loop)] // Index loops over vertices and components spell out the formulas.

use super::quality::IndexMap;
use super::{signed_measure, Facet, Mesh};

/// Vertex slot not used by a triangle.
const NONE: usize = usize::MAX;

/// The refinement data of one cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Marked {
    /// The vertices, refinement edge v[0]–v[1]; a triangle's newest vertex is v[2] (v[3]
    /// unused).
    v: [usize; 4],
    /// 3D: the marked edges of the faces opposite v[0] and v[1] (the two faces that hold the
    /// refinement edge are marked at it).
    faces: [[usize; 2]; 2],
    /// 3D: AMP's flag.
    flag: bool,
    /// Bisections since the mesh given to [`Bisection::new`].
    generation: u32,
}

/// A mesh with the refinement data of its cells, refined by bisection (see the module doc).
#[derive(Debug, Clone)]
pub struct Bisection<const D: usize> {
    mesh: Mesh<D>,
    cells: Vec<Marked>,
    /// 3D: the marked edge of each boundary facet (the one its cell marks on that face).
    facet_marks: Vec<[usize; 2]>,
}

/// One call of [`Bisection::refine`]: the refined mesh and how it nests in the previous one.
#[derive(Debug, Clone)]
pub struct Step<const D: usize> {
    /// The refined mesh (the same as [`Bisection::mesh`] after the call).
    pub mesh: Mesh<D>,
    /// For each cell of `mesh`, the cell of the previous mesh that contains it.
    pub parent: Vec<usize>,
    /// For each boundary facet of `mesh`, the facet of the previous mesh that contains it.
    pub facet_parent: Vec<usize>,
    /// The new nodes in index order (the first is the previous mesh's node count): node
    /// `n` is the midpoint of `a` and `b`, both below `n`.
    pub midpoints: Vec<(usize, [usize; 2])>,
}

/// Whether two edges are the same (either direction).
fn same(e: [usize; 2], f: [usize; 2]) -> bool {
    e == f || e == [f[1], f[0]]
}

/// Squared length of the edge a–b, computed from the lower-indexed node so that both cells
/// of an edge find the same number.
fn length2<const D: usize>(nodes: &[[f64; D]], a: usize, b: usize) -> f64 {
    let (p, q) = (nodes[a.min(b)], nodes[a.max(b)]);
    (0..D).map(|c| (q[c] - p[c]).powi(2)).sum()
}

/// Whether edge e comes before edge f in the global order: longer, or as long with the
/// lower sorted index pair.
fn before<const D: usize>(nodes: &[[f64; D]], e: [usize; 2], f: [usize; 2]) -> bool {
    let key = |e: [usize; 2]| [e[0].min(e[1]), e[0].max(e[1])];
    match length2(nodes, e[0], e[1]).total_cmp(&length2(nodes, f[0], f[1])) {
        std::cmp::Ordering::Greater => true,
        std::cmp::Ordering::Less => false,
        std::cmp::Ordering::Equal => key(e) < key(f),
    }
}

/// The first edge in the global order among the edges of the simplex `v`.
fn greatest<const D: usize>(nodes: &[[f64; D]], v: &[usize]) -> [usize; 2] {
    let mut best = [v[0], v[1]];
    for a in 0..v.len() {
        for b in a + 1..v.len() {
            if before(nodes, [v[a], v[b]], best) {
                best = [v[a], v[b]];
            }
        }
    }
    best
}

/// AMP's initial marking of a cell (3D), or its longest edge as refinement edge (2D), with
/// the cell's cyclic vertex order kept in 2D.
fn initial<const D: usize>(nodes: &[[f64; D]], cell: &[usize]) -> Marked {
    let e = greatest(nodes, cell);
    let mut m = Marked {
        v: [NONE; 4],
        faces: [[NONE; 2]; 2],
        flag: false,
        generation: 0,
    };
    if D == 2 {
        let k = (0..3).find(|&k| !e.contains(&cell[k])).unwrap();
        m.v[..3].copy_from_slice(&[cell[(k + 1) % 3], cell[(k + 2) % 3], cell[k]]);
    } else {
        let mut rest = cell.iter().copied().filter(|v| !e.contains(v));
        let (v2, v3) = (rest.next().unwrap(), rest.next().unwrap());
        m.v = [e[0], e[1], v2, v3];
        m.faces = [
            greatest(nodes, &[e[1], v2, v3]),
            greatest(nodes, &[e[0], v2, v3]),
        ];
    }
    m
}

/// The two children of `m`, bisected at the node z on its refinement edge.
fn bisect<const D: usize>(m: &Marked, z: usize) -> [Marked; 2] {
    let generation = m.generation + 1;
    if D == 2 {
        let [x0, x1, x2, _] = m.v;
        return [[x2, x0, z, NONE], [x1, x2, z, NONE]].map(|v| Marked {
            v,
            generation,
            ..*m
        });
    }
    let [x0, x1, x2, x3] = m.v;
    let [e0, e1] = m.faces;
    let planar = [x2, x3]
        .into_iter()
        .find(|&k| same(e0, [x1, k]) && same(e1, [x0, k]));
    let flagged_planar = planar.filter(|_| m.flag);
    // A cut face xi xj z is marked at xi–xj; the new face x2 x3 z at x2–x3, or at z–xk in
    // a flagged planar parent (which makes its children of type A).
    let mark = |p: usize, q: usize| match flagged_planar {
        Some(k) if same([p, q], [x2, x3]) => [z, k],
        _ => [p, q],
    };
    [0, 1].map(|i| {
        let [a, b] = m.faces[1 - i];
        let c = [m.v[i], x2, x3]
            .into_iter()
            .find(|&x| x != a && x != b)
            .unwrap();
        Marked {
            v: [a, b, c, z],
            faces: [mark(b, c), mark(a, c)],
            flag: planar.is_some() && !m.flag,
            generation,
        }
    })
}

/// The nodes and the edges bisected so far in one step.
struct Midpoints<const D: usize> {
    nodes: Vec<[f64; D]>,
    of: IndexMap<[usize; 2], usize>,
    list: Vec<(usize, [usize; 2])>,
}

impl<const D: usize> Midpoints<D> {
    fn get(&self, a: usize, b: usize) -> Option<usize> {
        self.of.get(&[a.min(b), a.max(b)]).copied()
    }

    fn get_or_add(&mut self, a: usize, b: usize) -> usize {
        let key = [a.min(b), a.max(b)];
        if let Some(&z) = self.of.get(&key) {
            return z;
        }
        let (p, q) = (self.nodes[key[0]], self.nodes[key[1]]);
        let z = self.nodes.len();
        self.nodes
            .push(std::array::from_fn(|c| 0.5 * (p[c] + q[c])));
        self.of.insert(key, z);
        self.list.push((z, key));
        z
    }
}

/// The bisection forest of one step: the previous cells are its roots 0..n.
struct Forest {
    marks: Vec<Marked>,
    kids: Vec<Option<[usize; 2]>>,
}

impl Forest {
    fn split<const D: usize>(&mut self, t: usize, mid: &mut Midpoints<D>) {
        let m = self.marks[t];
        let z = mid.get_or_add(m.v[0], m.v[1]);
        let n = self.marks.len();
        self.marks.extend(bisect::<D>(&m, z));
        self.kids.extend([None, None]);
        self.kids[t] = Some([n, n + 1]);
    }

    /// The leaves under root r, left to right.
    fn leaves(&self, r: usize, out: &mut Vec<usize>) {
        let mut stack = vec![r];
        while let Some(t) = stack.pop() {
            match self.kids[t] {
                Some([a, b]) => stack.extend([b, a]),
                None => out.push(t),
            }
        }
    }
}

/// The facet `nodes` (ordered along its outward normal) split at every bisected edge, left
/// to right; `mark` its marked edge (3D; unused in 2D).
fn split_facet<const D: usize>(
    mid: &Midpoints<D>,
    nodes: [usize; D],
    mark: [usize; 2],
    out: &mut Vec<([usize; D], [usize; 2])>,
) {
    let mut stack = vec![(nodes, mark)];
    while let Some((f, mark)) = stack.pop() {
        if D == 2 {
            match mid.get(f[0], f[1]) {
                Some(z) => {
                    let half = |p: usize, q: usize| std::array::from_fn(|c| [p, q][c]);
                    stack.push((half(z, f[1]), mark));
                    stack.push((half(f[0], z), mark));
                }
                None => out.push((f, mark)),
            }
            continue;
        }
        // Rotate (keeping the cyclic order, hence the normal) so the mark is f[0]–f[1].
        let i = (0..3)
            .find(|&i| same([f[i], f[(i + 1) % 3]], mark))
            .expect("a facet's mark is one of its edges");
        let (p, q, r) = (f[i], f[(i + 1) % 3], f[(i + 2) % 3]);
        match mid.get(p, q) {
            Some(z) => {
                let tri = |a: usize, b: usize, c: usize| std::array::from_fn(|k| [a, b, c][k]);
                stack.push((tri(z, q, r), [q, r]));
                stack.push((tri(p, z, r), [p, r]));
            }
            None => out.push((f, mark)),
        }
    }
}

/// |F| of a facet from its nodes: length (2D) or area (3D).
fn facet_measure<const D: usize>(nodes: &[[f64; D]], f: &[usize; D]) -> f64 {
    let p = nodes[f[0]];
    let d = |k: usize| -> [f64; 3] {
        std::array::from_fn(|c| if c < D { nodes[f[k]][c] - p[c] } else { 0.0 })
    };
    let a = d(1);
    if D == 2 {
        return a[0].hypot(a[1]);
    }
    let b = d(2);
    let n = [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ];
    0.5 * n.iter().map(|v| v * v).sum::<f64>().sqrt()
}

impl<const D: usize> Bisection<D> {
    /// The refinement data of `mesh` as given: the initial marking of the module doc.
    pub fn new(mesh: &Mesh<D>) -> Bisection<D> {
        let cells = mesh.cells().map(|c| initial(&mesh.nodes, c)).collect();
        let facet_marks = if D == 3 {
            mesh.facets
                .iter()
                .map(|f| greatest(&mesh.nodes, &f.nodes))
                .collect()
        } else {
            Vec::new()
        };
        Bisection {
            mesh: mesh.clone(),
            cells,
            facet_marks,
        }
    }

    /// The current mesh.
    pub fn mesh(&self) -> &Mesh<D> {
        &self.mesh
    }

    /// How many bisections made cell `cell` from a cell of the mesh given to [`Self::new`].
    pub fn generation(&self, cell: usize) -> usize {
        self.cells[cell].generation as usize
    }

    /// Bisects every cell in `marked` once (repeats count once), then closes the mesh
    /// (module doc), and returns the step. An empty list returns the mesh as it is (its
    /// grid, lattice and nesting included).
    ///
    /// Panics if a marked index is not a cell of the current mesh.
    pub fn refine(&mut self, marked: &[usize]) -> Step<D> {
        let old = &self.mesh;
        let n = old.n_cells();
        let mut marked = marked.to_vec();
        marked.sort_unstable();
        marked.dedup();
        match marked.last() {
            Some(&c) => assert!(c < n, "marked cell {c}, but the mesh has {n} cells"),
            None => {
                return Step {
                    mesh: old.clone(),
                    parent: (0..n).collect(),
                    facet_parent: (0..old.facets.len()).collect(),
                    midpoints: Vec::new(),
                }
            }
        }

        let mut mid = Midpoints {
            nodes: old.nodes.clone(),
            of: IndexMap::default(),
            list: Vec::new(),
        };
        let mut forest = Forest {
            marks: self.cells.clone(),
            kids: vec![None; n],
        };
        for &c in &marked {
            forest.split(c, &mut mid);
        }
        // Sweeps until no leaf has a hanging node; a sweep also visits the leaves it makes.
        let edges: &[[usize; 2]] = if D == 2 {
            &[[0, 1], [0, 2], [1, 2]]
        } else {
            &[[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]
        };
        let mut changed = true;
        while changed {
            changed = false;
            let mut t = 0;
            while t < forest.marks.len() {
                let v = forest.marks[t].v;
                if forest.kids[t].is_none()
                    && edges.iter().any(|&[a, b]| mid.get(v[a], v[b]).is_some())
                {
                    forest.split(t, &mut mid);
                    changed = true;
                }
                t += 1;
            }
        }

        // Cells: the leaves of each root in order; untouched cells as they were.
        let mut cells = Vec::with_capacity((D + 1) * (n + 2 * (forest.marks.len() - n)));
        let mut marks = Vec::with_capacity(cells.capacity() / (D + 1));
        let mut parent = Vec::with_capacity(marks.capacity());
        let mut leaves = Vec::new();
        for r in 0..n {
            if forest.kids[r].is_none() {
                cells.extend_from_slice(old.cell(r));
                marks.push(forest.marks[r]);
                parent.push(r);
                continue;
            }
            let simplex = |v: &[usize]| -> f64 {
                let p: Vec<[f64; D]> = v.iter().map(|&i| mid.nodes[i]).collect();
                signed_measure(&p)
            };
            let positive = simplex(old.cell(r)) > 0.0;
            leaves.clear();
            forest.leaves(r, &mut leaves);
            for &t in &leaves {
                let m = forest.marks[t];
                let mut v = m.v;
                if (simplex(&v[..=D]) > 0.0) != positive {
                    v.swap(0, 1);
                }
                cells.extend_from_slice(&v[..=D]);
                marks.push(m);
                parent.push(r);
            }
        }

        // Boundary facets: each old facet's pieces in order, and the groups' indices with them.
        let mut facets = Vec::with_capacity(old.facets.len());
        let mut facet_marks = Vec::with_capacity(self.facet_marks.len());
        let mut first = Vec::with_capacity(old.facets.len() + 1);
        let mut facet_parent = Vec::with_capacity(old.facets.len());
        let mut pieces = Vec::new();
        for (i, f) in old.facets.iter().enumerate() {
            first.push(facets.len());
            let mark = if D == 3 {
                self.facet_marks[i]
            } else {
                [f.nodes[0], f.nodes[1]]
            };
            pieces.clear();
            split_facet(&mid, f.nodes, mark, &mut pieces);
            if pieces.len() == 1 {
                facets.push(*f);
            } else {
                facets.extend(pieces.iter().map(|&(nodes, _)| Facet {
                    nodes,
                    measure: facet_measure(&mid.nodes, &nodes),
                    ..*f
                }));
            }
            facet_parent.resize(facets.len(), i);
            if D == 3 {
                facet_marks.extend(pieces.iter().map(|&(_, m)| m));
            }
        }
        first.push(facets.len());
        let groups = old
            .groups
            .iter()
            .map(|g| g.refined(|f| first[f]..first[f + 1]))
            .collect();

        let mesh = Mesh::from_parts(mid.nodes, cells, facets, groups, Vec::new());
        self.mesh = mesh.clone();
        self.cells = marks;
        self.facet_marks = facet_marks;
        Step {
            mesh,
            parent,
            facet_parent,
            midpoints: mid.list,
        }
    }
}

#[cfg(test)]
mod tests;
