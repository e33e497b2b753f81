//! Geometry only: nodes, triangles and boundary edges tagged with the boundary part that
//! contains them. The structured generator (docs/numerics.md#mesh-patterns-refinement-and-nesting): n = round(1/h) cells per unit
//! length, every square cell cut by its lower-left → upper-right diagonal (default), so the
//! meshes of h and h/2 are nested.

pub mod polygon;
use crate::problem::{MeshPattern, Segment};

/// A boundary edge of the mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoundaryEdge {
    /// End nodes, ordered so that the body lies to the left (counter-clockwise boundary).
    pub nodes: [usize; 2],
    /// Outward unit normal.
    pub normal: [f64; 2],
    pub length: f64,
    /// Index of the boundary part that contains the edge, None if traction-free.
    pub part: Option<usize>,
}

/// A triangulation of the rectangle [0, width] × [0, height].
#[derive(Debug, Clone)]
pub struct Mesh {
    pub nodes: Vec<[f64; 2]>,
    /// Counter-clockwise vertex triples.
    pub triangles: Vec<[usize; 3]>,
    pub boundary_edges: Vec<BoundaryEdge>,
    pub width: f64,
    pub height: f64,
    /// Cells along x and y.
    pub nx: usize,
    pub ny: usize,
    pub pattern: MeshPattern,
}

impl Mesh {
    /// Structured mesh of nx × ny square (or rectangular) cells.
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
        let mut triangles = Vec::with_capacity(nx * ny * per_cell);
        for j in 0..ny {
            for i in 0..nx {
                let (a, b, c, d) = (
                    grid(i, j),
                    grid(i + 1, j),
                    grid(i + 1, j + 1),
                    grid(i, j + 1),
                );
                match pattern {
                    MeshPattern::Diagonal => {
                        triangles.push([a, b, c]);
                        triangles.push([a, c, d]);
                    }
                    MeshPattern::AntiDiagonal => {
                        triangles.push([a, b, d]);
                        triangles.push([b, c, d]);
                    }
                    MeshPattern::Cross => {
                        let m = nodes.len();
                        nodes.push([(i as f64 + 0.5) * hx, (j as f64 + 0.5) * hy]);
                        triangles.extend_from_slice(&[[a, b, m], [b, c, m], [c, d, m], [d, a, m]]);
                    }
                }
            }
        }
        let mut boundary_edges = Vec::with_capacity(2 * (nx + ny));
        let mut edge = |p: usize, q: usize, normal: [f64; 2], length: f64| {
            boundary_edges.push(BoundaryEdge {
                nodes: [p, q],
                normal,
                length,
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
            triangles,
            boundary_edges,
            width,
            height,
            nx,
            ny,
            pattern,
        }
    }

    /// Tags each boundary edge with the first part whose segment contains it (docs/numerics.md#boundary-tagging: "a
    /// boundary edge belongs to the part that contains it"); parts do not overlap (validated).
    pub fn tag_boundary(&mut self, segments: &[Segment]) {
        let tol = 1e-9 * self.width.max(self.height);
        for e in &mut self.boundary_edges {
            let (p, q) = (self.nodes[e.nodes[0]], self.nodes[e.nodes[1]]);
            e.part = segments
                .iter()
                .position(|s| on_segment(p, s, tol) && on_segment(q, s, tol));
        }
    }

    pub fn n_nodes(&self) -> usize {
        self.nodes.len()
    }

    /// Area of triangle t.
    pub fn area(&self, t: usize) -> f64 {
        let [a, b, c] = self.triangles[t].map(|i| self.nodes[i]);
        0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]))
    }
}

/// Is point p on the closed segment s (within tol)?
fn on_segment(p: [f64; 2], s: &Segment, tol: f64) -> bool {
    let d = [s.b[0] - s.a[0], s.b[1] - s.a[1]];
    let len2 = d[0] * d[0] + d[1] * d[1];
    let v = [p[0] - s.a[0], p[1] - s.a[1]];
    let t = (v[0] * d[0] + v[1] * d[1]) / len2;
    let len = len2.sqrt();
    let dist = (v[0] * d[1] - v[1] * d[0]).abs() / len;
    dist <= tol && t * len >= -tol && (t - 1.0) * len <= tol
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_areas_and_orientation() {
        for (pattern, tri_per_cell, extra) in [
            (MeshPattern::Diagonal, 2, 0),
            (MeshPattern::AntiDiagonal, 2, 0),
            (MeshPattern::Cross, 4, 1),
        ] {
            let m = Mesh::rectangle(2.0, 1.0, 8, 4, pattern);
            assert_eq!(m.n_nodes(), 9 * 5 + extra * 32);
            assert_eq!(m.triangles.len(), tri_per_cell * 32);
            let total: f64 = (0..m.triangles.len()).map(|t| m.area(t)).sum();
            assert!((total - 2.0).abs() < 1e-13);
            assert!((0..m.triangles.len()).all(|t| m.area(t) > 0.0));
            let perimeter: f64 = m.boundary_edges.iter().map(|e| e.length).sum();
            assert!((perimeter - 6.0).abs() < 1e-13);
        }
    }

    #[test]
    fn tagging_uses_containment() {
        let mut m = Mesh::rectangle(2.0, 1.0, 4, 2, MeshPattern::Diagonal);
        // Experiment 2's Γ3 = [0, 1) × {0}: the two bottom edges left of x = 1.
        let seg = Segment {
            a: [0.0, 0.0],
            b: [1.0, 0.0],
        };
        m.tag_boundary(&[seg]);
        let tagged: Vec<_> = m
            .boundary_edges
            .iter()
            .filter(|e| e.part == Some(0))
            .collect();
        assert_eq!(tagged.len(), 2);
        assert!(tagged.iter().all(|e| e.normal == [0.0, -1.0]));
    }
}
