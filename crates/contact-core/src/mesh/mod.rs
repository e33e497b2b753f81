//! Geometry only: nodes, simplicial cells (triangles in 2D, tetrahedra in 3D) and boundary
//! facets tagged with the boundary part that contains them, for any dimension `D` (2 or 3).
//!
//! Where meshes come from (docs/src/explanation/numerics.md#meshes):
//! - [`Mesh::rectangle`]: the structured generator. n = round(1/h) cells per unit length,
//!   every square cell cut by its lower-left → upper-right diagonal (default), so the meshes
//!   of h and h/2 are nested.
//! - [`Mesh::cuboid`] ([`cuboid`]): the structured box, every cuboid cell cut into the 6 Kuhn
//!   tetrahedra, so that the boxes of h and h/2 are nested.
//! - [`Mesh::from_cells`] (used by [`import`] for gmsh files and by the polygon mesher): any
//!   conforming simplicial mesh, checked by [`quality`] and with its boundary facets found
//!   as the faces that belong to one cell only.
//! - [`Mesh::refine`] ([`refine`]): uniform (red) refinement, nested by construction.
//! - [`bisect::Bisection`] ([`bisect`]): local refinement by bisection with a conforming
//!   closure, nested, each step described by its [`bisect::Step`].
//!
//! Boundary parts are tagged once on the mesh given by the user ([`support`]); refinement
//! hands each child facet its parent's tag, so curved parts stay selected although the new
//! nodes lie on chords.

#![allow(clippy::needless_range_loop)] // Index loops over vertices and components spell out the formulas.

pub mod any;
pub mod bisect;
pub mod cuboid;
pub mod export;
pub mod import;
pub mod locality;
pub mod polygon;
pub mod quality;
pub mod refine;
pub mod support;

pub use any::{AnyMesh, SharedMesh};
pub use quality::MeshError;

/// How each square cell of the structured mesh is cut into triangles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MeshPattern {
    /// Lower-left → upper-right diagonal (the default; docs/src/explanation/numerics.md#the-three-patterns).
    Diagonal,
    /// Lower-right → upper-left diagonal.
    AntiDiagonal,
    /// Both diagonals: four triangles around an added cell-centre node.
    Cross,
}

/// A straight piece of the rectangle's boundary, from `a` to `b`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    pub a: [f64; 2],
    pub b: [f64; 2],
}

/// A boundary facet: an edge in 2D, a triangle in 3D.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Facet<const D: usize> {
    /// Vertices, ordered so that the outward normal follows them (2D: the body lies to the
    /// left of p → q; 3D: counter-clockwise seen from outside).
    pub nodes: [usize; D],
    /// Outward unit normal ν_F.
    pub normal: [f64; D],
    /// |F|: length (2D) or area (3D).
    pub measure: f64,
    /// Index of the boundary part that contains the facet, None if traction-free.
    pub part: Option<usize>,
}

/// The lattice of a structured rectangle mesh (what nesting of rectangles relies on).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grid {
    pub width: f64,
    pub height: f64,
    /// Cells along x and y.
    pub nx: usize,
    pub ny: usize,
    pub pattern: MeshPattern,
}

/// The lattice of a structured box ([`Mesh::cuboid`]; what nesting of boxes relies on).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lattice {
    /// (lx, ly, lz): the box is [0, lx] × [0, ly] × [0, lz].
    pub size: [f64; 3],
    /// (nx, ny, nz): cuboid cells along x, y and z.
    pub cells: [usize; 3],
}

/// A named set of boundary facets: a physical group of an imported mesh.
#[derive(Debug, Clone, PartialEq)]
pub struct Group {
    /// The name from `$PhysicalNames`, or the physical tag written as a number.
    pub name: String,
    /// Indices into [`Mesh::facets`].
    pub facets: Vec<usize>,
}

impl Group {
    /// The same group on a refined mesh whose facets `children(f)` replace facet f.
    pub fn refined(&self, children: impl Fn(usize) -> std::ops::Range<usize>) -> Group {
        Group {
            name: self.name.clone(),
            facets: self.facets.iter().flat_map(|&f| children(f)).collect(),
        }
    }
}

/// How one red refinement relates to its coarse mesh: the first `coarse_nodes` nodes are the
/// coarse nodes, node `coarse_nodes + k` is the midpoint of coarse edge `midpoints[k]`, and
/// the children of coarse cell c are cells 2^D·c .. 2^D·c + 2^D − 1. The levels of an
/// adaptive study's bisected meshes use the same form for their nodes (a midpoint's ends may
/// then be earlier midpoints; the cells are not related this way).
#[derive(Debug, Clone, PartialEq)]
pub struct Nesting {
    pub coarse_nodes: usize,
    pub midpoints: Vec<[usize; 2]>,
}

/// A conforming simplicial mesh of a body in R^D.
#[derive(Debug, Clone)]
pub struct Mesh<const D: usize = 2> {
    pub nodes: Vec<[f64; D]>,
    /// D + 1 node indices per cell, flat, in the order given (either orientation; every
    /// quantity uses unsigned measures and geometric outward normals).
    cells: Vec<usize>,
    pub facets: Vec<Facet<D>>,
    pub groups: Vec<Group>,
    /// Set for the structured rectangle.
    pub grid: Option<Grid>,
    /// Set for the structured box (as for `grid`, not for its red refinements).
    pub lattice: Option<Lattice>,
    /// One entry per red refinement that made this mesh from the mesh as given, coarsest
    /// first (empty for a mesh as given).
    pub nesting: Vec<Nesting>,
}

impl<const D: usize> Mesh<D> {
    /// Vertices per cell.
    pub const CELL: usize = D + 1;

    pub fn n_nodes(&self) -> usize {
        self.nodes.len()
    }

    pub fn n_cells(&self) -> usize {
        self.cells.len() / (D + 1)
    }

    /// The vertices of cell e.
    #[inline]
    pub fn cell(&self, e: usize) -> &[usize] {
        &self.cells[(D + 1) * e..(D + 1) * (e + 1)]
    }

    /// The cells in order, D + 1 vertices each.
    pub fn cells(&self) -> std::slice::ChunksExact<'_, usize> {
        self.cells.chunks_exact(D + 1)
    }

    /// The cells' node indices, D + 1 per cell, flat.
    pub fn cells_flat(&self) -> &[usize] {
        &self.cells
    }

    /// The smallest box [min, max] that holds every node.
    pub fn bounding_box(&self) -> ([f64; D], [f64; D]) {
        let mut lo = [f64::INFINITY; D];
        let mut hi = [f64::NEG_INFINITY; D];
        for p in &self.nodes {
            for c in 0..D {
                lo[c] = lo[c].min(p[c]);
                hi[c] = hi[c].max(p[c]);
            }
        }
        (lo, hi)
    }

    /// The length of the bounding box's diagonal: the scale of geometric tolerances.
    pub fn diameter(&self) -> f64 {
        let (lo, hi) = self.bounding_box();
        (0..D).map(|c| (hi[c] - lo[c]).powi(2)).sum::<f64>().sqrt()
    }

    /// Tags every boundary facet with the part that selects it (docs/src/explanation/numerics.md#boundary-tagging).
    pub fn tag_boundary(&mut self, supports: &[support::Support]) -> Result<(), support::TagError> {
        support::tag(self, supports)
    }

    /// One uniform (red) refinement ([`refine`]).
    pub fn refine(&self) -> Mesh<D> {
        refine::red(self)
    }

    /// A mesh of the given cells, checked ([`quality`]) and with its boundary facets found.
    pub fn from_cells(nodes: Vec<[f64; D]>, cells: Vec<usize>) -> Result<Mesh<D>, MeshError> {
        quality::build(nodes, cells)
    }

    pub(crate) fn from_parts(
        nodes: Vec<[f64; D]>,
        cells: Vec<usize>,
        facets: Vec<Facet<D>>,
        groups: Vec<Group>,
        nesting: Vec<Nesting>,
    ) -> Mesh<D> {
        debug_assert_eq!(cells.len() % (D + 1), 0);
        Mesh {
            nodes,
            cells,
            facets,
            groups,
            grid: None,
            lattice: None,
            nesting,
        }
    }
}

/// Signed measure of a simplex: half the 2D cross product, or a sixth of the 3D triple
/// product (positive for counter-clockwise / right-handed vertex order).
pub fn signed_measure<const D: usize>(p: &[[f64; D]]) -> f64 {
    let d = |k: usize, c: usize| p[k][c] - p[0][c];
    match D {
        2 => 0.5 * (d(1, 0) * d(2, 1) - d(2, 0) * d(1, 1)),
        3 => {
            (d(1, 0) * (d(2, 1) * d(3, 2) - d(2, 2) * d(3, 1))
                - d(1, 1) * (d(2, 0) * d(3, 2) - d(2, 2) * d(3, 0))
                + d(1, 2) * (d(2, 0) * d(3, 1) - d(2, 1) * d(3, 0)))
                / 6.0
        }
        _ => unreachable!("meshes are 2D or 3D"),
    }
}

/// The outward unit normal and measure of the facet `f` of a cell whose remaining vertex is
/// `opposite`, with the facet's vertices reordered to follow the normal ([`Facet::nodes`]).
pub fn facet_frame<const D: usize>(
    nodes: &[[f64; D]],
    mut f: [usize; D],
    opposite: [f64; D],
) -> ([usize; D], [f64; D], f64) {
    let p = nodes[f[0]];
    let mut n = [0.0; D];
    match D {
        2 => {
            let q = nodes[f[1]];
            n[0] = q[1] - p[1];
            n[1] = p[0] - q[0];
        }
        3 => {
            let (q, r) = (nodes[f[1]], nodes[f[2]]);
            let (a, b) = (
                [q[0] - p[0], q[1] - p[1], q[2] - p[2]],
                [r[0] - p[0], r[1] - p[1], r[2] - p[2]],
            );
            n[0] = a[1] * b[2] - a[2] * b[1];
            n[1] = a[2] * b[0] - a[0] * b[2];
            n[2] = a[0] * b[1] - a[1] * b[0];
        }
        _ => unreachable!("meshes are 2D or 3D"),
    }
    let inward: f64 = (0..D).map(|c| n[c] * (opposite[c] - p[c])).sum();
    if inward > 0.0 {
        f.swap(D - 2, D - 1);
        n.iter_mut().for_each(|v| *v = -*v);
    }
    let len = n.iter().map(|v| v * v).sum::<f64>().sqrt();
    let measure = if D == 2 { len } else { 0.5 * len };
    (f, n.map(|v| v / len), measure)
}

impl Mesh<2> {
    /// Structured mesh of nx × ny square (or rectangular) cells of [0, width] × [0, height].
    pub fn rectangle(width: f64, height: f64, nx: usize, ny: usize, pattern: MeshPattern) -> Mesh {
        assert!(nx >= 1 && ny >= 1);
        let hx = width / nx as f64;
        let hy = height / ny as f64;
        let grid = |i: usize, j: usize| j * (nx + 1) + i;
        let mut nodes = Vec::with_capacity((nx + 1) * (ny + 1));
        for j in 0..=ny {
            for i in 0..=nx {
                // Multiply rather than accumulate so nested meshes share bit-identical nodes.
                nodes.push([i as f64 * hx, j as f64 * hy]);
            }
        }
        let per_cell = if pattern == MeshPattern::Cross { 4 } else { 2 };
        let mut cells = Vec::with_capacity(3 * nx * ny * per_cell);
        for j in 0..ny {
            for i in 0..nx {
                let (a, b, c, d) = (
                    grid(i, j),
                    grid(i + 1, j),
                    grid(i + 1, j + 1),
                    grid(i, j + 1),
                );
                match pattern {
                    MeshPattern::Diagonal => cells.extend_from_slice(&[a, b, c, a, c, d]),
                    MeshPattern::AntiDiagonal => cells.extend_from_slice(&[a, b, d, b, c, d]),
                    MeshPattern::Cross => {
                        let m = nodes.len();
                        nodes.push([(i as f64 + 0.5) * hx, (j as f64 + 0.5) * hy]);
                        cells.extend_from_slice(&[a, b, m, b, c, m, c, d, m, d, a, m]);
                    }
                }
            }
        }
        let mut facets = Vec::with_capacity(2 * (nx + ny));
        let mut edge = |p: usize, q: usize, normal: [f64; 2], measure: f64| {
            facets.push(Facet {
                nodes: [p, q],
                normal,
                measure,
                part: None,
            })
        };
        for i in 0..nx {
            edge(grid(i, 0), grid(i + 1, 0), [0.0, -1.0], hx);
        }
        for j in 0..ny {
            edge(grid(nx, j), grid(nx, j + 1), [1.0, 0.0], hy);
        }
        for i in (0..nx).rev() {
            edge(grid(i + 1, ny), grid(i, ny), [0.0, 1.0], hx);
        }
        for j in (0..ny).rev() {
            edge(grid(0, j + 1), grid(0, j), [-1.0, 0.0], hy);
        }
        Mesh {
            nodes,
            cells,
            facets,
            groups: Vec::new(),
            grid: Some(Grid {
                width,
                height,
                nx,
                ny,
                pattern,
            }),
            lattice: None,
            nesting: Vec::new(),
        }
    }

    /// The triangles as vertex triples.
    pub fn triangles(&self) -> &[[usize; 3]] {
        self.cells.as_chunks::<3>().0
    }

    /// The vertices of triangle t.
    #[inline]
    pub fn triangle(&self, t: usize) -> [usize; 3] {
        self.triangles()[t]
    }

    /// Area of triangle t (positive for counter-clockwise vertices).
    pub fn area(&self, t: usize) -> f64 {
        signed_measure(&self.triangle(t).map(|i| self.nodes[i]))
    }
}

/// Is point p on the closed segment s (within tol)?
pub(crate) fn on_segment(p: [f64; 2], s: &Segment, tol: f64) -> bool {
    let d = [s.b[0] - s.a[0], s.b[1] - s.a[1]];
    let len2 = d[0] * d[0] + d[1] * d[1];
    let v = [p[0] - s.a[0], p[1] - s.a[1]];
    let t = (v[0] * d[0] + v[1] * d[1]) / len2;
    let len = len2.sqrt();
    let dist = (v[0] * d[1] - v[1] * d[0]).abs() / len;
    dist <= tol && t * len >= -tol && (t - 1.0) * len <= tol
}

#[cfg(test)]
mod tests;
