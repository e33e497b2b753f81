//! Unstructured triangulation of a polygon with holes, in process (no gmsh).
//!
//! # Algorithm
//!
//! 1. **Validation** (exact, before any meshing). Each ring needs ≥ 3 vertices with finite
//!    coordinates of magnitude 0 or in [`MIN_COORDINATE`, `MAX_COORDINATE`] and no vertex
//!    equal to the next. The rings are then loaded, unsubdivided, into a constrained Delaunay
//!    triangulation (spade, exact predicates) whose constraint edges are the ring edges: a
//!    repeated position, a constraint that crosses another, or one that passes through a
//!    vertex is a self-intersection or two rings meeting, and the culprit pair of edges is
//!    found by an exact scan (`robust::orient2d`). With the rings simple and disjoint, the
//!    number of ring edges a path from infinity must cross to reach a face (a 0-1
//!    breadth-first search over the faces) is the number of rings enclosing it, which tells
//!    a hole outside the outer ring (0) from one inside another hole (2). Either orientation
//!    of every ring is accepted.
//! 2. **Size bound** before meshing: every triangle of a complete refinement has area at
//!    most `A_max = √3/4·h²`, so with `B` boundary nodes Euler's formula gives at least
//!    `(area/A_max + B)/2` nodes (less the holes count, ignored). Above `max_nodes` the call
//!    is refused before any allocation proportional to the mesh; the refinement itself is
//!    also capped at `max_nodes` vertices, so hostile input cannot make it run away.
//! 3. **Boundary nodes**: polygon edge `p → q` of length `L` becomes `n = ⌈L/h⌉` equal pieces,
//!    nodes `p + (k/n)(q − p)`, so the polygon vertices are mesh nodes and straight polygon
//!    edges stay straight. The rings' pieces are the constraint edges of a second
//!    constrained Delaunay triangulation (checked as in 1: rounding of the subdivision
//!    points could only matter for rings closer than about 1e-15 of their size).
//! 4. **Refinement** (spade's Ruppert/Chew Delaunay refinement): a triangle whose
//!    circumradius exceeds its shortest edge (an angle below [`MIN_ANGLE_DEG`] = 30°) or
//!    whose area exceeds `A_max` (the equilateral triangle of side h) gets its circumcentre
//!    inserted; faces outside the region are excluded. The first pass keeps the constraint
//!    edges, so the boundary nodes are exactly those of step 3. Its mesh is accepted if every
//!    edge is at most 1.5 h and every angle at least 20°, except in triangles at a polygon
//!    corner sharper than 40° (whose angle no mesh can improve). Otherwise the geometry has
//!    features narrower than h (a strip thinner than h, a polygon edge much shorter than its
//!    neighbours' pieces) and pieces of length h cannot be kept: a second pass, from scratch,
//!    lets the refinement split the pieces that a new point would encroach on (at their
//!    midpoints, later at power-of-two distances from a polygon vertex). The nodes it adds
//!    lie on the pieces up to rounding and are numbered among the refinement points.
//! 5. **Extraction**: the faces enclosed by exactly one ring (the crossing count of 1) are
//!    the mesh. Nodes are spade's vertices in spade's order, unused ones dropped: first the
//!    boundary nodes of step 3 ring by ring (outer, then holes in order) and in input order
//!    along each ring, then refinement points in order of insertion. Each triangle is
//!    spade's counter-clockwise triple, rotated to start at its smallest node; the list is
//!    sorted.
//!
//! # Determinism
//!
//! Everything above is a fixed sequence of IEEE operations on the input: spade's bulk load
//! and refinement are deterministic for a fixed insertion order (its hash maps are only
//! probed, never iterated into the result; no threads), the angle bound is given as the
//! exact ratio 1 rather than a sine, and the acceptance test of step 4 uses square roots
//! only. So the same input gives the bit-identical output on every machine for a given
//! build (`output_is_deterministic` pins a fingerprint). Two caveats: the second pass's
//! power-of-two split calls `log2` (libm), which could differ between platforms only at a
//! rounding tie at k + ½; and another spade release (it allows patch releases to refine
//! differently) or a change of the standard library's unstable sort, which spade's bulk
//! load uses on distance ties, may change the output, which is one reason Cargo.lock pins
//! spade.
//!
//! # Why spade
//!
//! Constrained Delaunay refinement gives a guaranteed minimum angle away from small input
//! angles and sizes graded to the geometry, in pure safe Rust with exact predicates; it
//! meshes ~100k cells in a fraction of a second, so no external mesher is needed for plane
//! polygons.

use spade::handles::FixedVertexHandle;
use spade::{
    AngleLimit, ConstrainedDelaunayTriangulation, Point2, RefinementParameters, Triangulation as _,
};
use std::collections::VecDeque;
use std::fmt;

#[cfg(test)]
mod tests;

/// The minimum angle requested from the refinement, in degrees (passed to spade as the
/// equivalent ratio 1 of circumradius to shortest edge). Up to 30° the refinement terminates
/// on its own; angles of the input polygon below it stay as they are.
pub const MIN_ANGLE_DEG: f64 = 30.0;

/// The largest accepted coordinate magnitude (squares of differences stay far from overflow).
pub const MAX_COORDINATE: f64 = 1e30;

/// The smallest accepted non-zero coordinate magnitude (spade refuses magnitudes below 2⁻¹⁴²).
pub const MIN_COORDINATE: f64 = 1e-30;

/// A triangulation of a polygon with holes: nodes and counter-clockwise triangles.
#[derive(Debug, Clone, PartialEq)]
pub struct Triangulation {
    /// Node coordinates `[x, y]`; every node is a vertex of some triangle.
    pub nodes: Vec<[f64; 2]>,
    /// Node index triples, each counter-clockwise (positive signed area).
    pub triangles: Vec<[usize; 3]>,
}

/// One ring of the input: the outer boundary or `holes[i]`. Displayed as "the outer
/// boundary" or "hole i" (i from 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Ring {
    /// The `outer` argument.
    Outer,
    /// Index into `holes`.
    Hole(usize),
}

impl fmt::Display for Ring {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Ring::Outer => write!(f, "the outer boundary"),
            Ring::Hole(i) => write!(f, "hole {i}"),
        }
    }
}

/// Why a polygon was not meshed. Vertex indices are positions in the ring's slice (from 0);
/// an edge is named by its first vertex (edge `i` joins vertex `i` and the next one).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PolygonError {
    #[error("the mesh size h must be a finite positive number, not {h}")]
    InvalidSize { h: f64 },
    #[error("{ring} has {count} vertices; a polygon needs at least 3")]
    TooFewVertices { ring: Ring, count: usize },
    #[error("vertex {vertex} of {ring} has a coordinate that is not a finite number")]
    NonFiniteCoordinate { ring: Ring, vertex: usize },
    #[error(
        "vertex {vertex} of {ring} has the coordinate {value:e}; coordinates must be 0 or \
         of magnitude between {MIN_COORDINATE:e} and {MAX_COORDINATE:e}"
    )]
    CoordinateOutOfRange {
        ring: Ring,
        vertex: usize,
        value: f64,
    },
    #[error(
        "vertices {vertex} and {next} of {ring} are the same point (list each corner once, \
         without repeating the first vertex at the end)"
    )]
    RepeatedVertex {
        ring: Ring,
        vertex: usize,
        next: usize,
    },
    #[error("{ring} encloses no area")]
    ZeroArea { ring: Ring },
    #[error(
        "{ring} intersects itself: its edge from vertex {edge} crosses or touches its edge \
         from vertex {other_edge}"
    )]
    SelfIntersecting {
        ring: Ring,
        edge: usize,
        other_edge: usize,
    },
    #[error(
        "{ring} and {other_ring} intersect: edge {edge} of {ring} crosses or touches \
         edge {other_edge} of {other_ring}"
    )]
    RingsIntersect {
        ring: Ring,
        edge: usize,
        other_ring: Ring,
        other_edge: usize,
    },
    #[error("hole {hole} is not inside the outer boundary")]
    HoleOutside { hole: usize },
    #[error("hole {hole} lies inside hole {container}; holes may not be nested")]
    HolesNested { hole: usize, container: usize },
    #[error(
        "{ring} near its edge from vertex {edge} comes too close to another part of the \
         boundary to be meshed (closer than rounding of the coordinates can resolve)"
    )]
    BoundaryTooClose { ring: Ring, edge: usize },
    #[error(
        "the mesh at h = {h} would have at least {at_least} nodes, more than the limit of \
         {max_nodes}; choose a larger h"
    )]
    TooManyNodes {
        h: f64,
        at_least: usize,
        max_nodes: usize,
    },
    #[error("the mesher failed on this polygon: {reason}")]
    MeshingFailed { reason: String },
}

impl PolygonError {
    /// The ring and vertex (or edge, by its first vertex) the error is about, if any; `None`
    /// for the size h and for the mesher itself.
    pub fn place(&self) -> Option<(Ring, Option<usize>)> {
        use PolygonError::*;
        match self {
            TooFewVertices { ring, .. } | ZeroArea { ring } => Some((*ring, None)),
            NonFiniteCoordinate { ring, vertex }
            | CoordinateOutOfRange { ring, vertex, .. }
            | RepeatedVertex { ring, vertex, .. } => Some((*ring, Some(*vertex))),
            SelfIntersecting { ring, edge, .. }
            | RingsIntersect { ring, edge, .. }
            | BoundaryTooClose { ring, edge } => Some((*ring, Some(*edge))),
            HoleOutside { hole } | HolesNested { hole, .. } => Some((Ring::Hole(*hole), None)),
            InvalidSize { .. } | TooManyNodes { .. } | MeshingFailed { .. } => None,
        }
    }
}

type Cdt = ConstrainedDelaunayTriangulation<Point2<f64>>;

/// Meshes the region inside `outer` and outside every hole at size h.
///
/// `outer` and each of `holes` are closed rings of `[x, y]` vertices, each corner listed
/// once (the closing edge is implicit), in either orientation; holes must lie strictly
/// inside `outer` and outside each other, and no two edges may touch except consecutive
/// edges of a ring at their common vertex. `h` (> 0) is the target edge length: polygon
/// edges are cut into ⌈length/h⌉ equal pieces, triangles are refined to areas of at most
/// √3/4·h² and angles of 30° (edges come out below about 1.4 h; finer near features smaller
/// than h). `max_nodes` bounds the output's node count: a polygon that needs more is
/// refused, before meshing when the lower bound `(area/(√3/4·h²) + boundary nodes)/2`
/// already exceeds it (a complete mesh has about 1.6 times that).
///
/// Returns `nodes` (N × 2) and `triangles` (T × 3, counter-clockwise, into `nodes`); the
/// N nodes begin with the boundary nodes of the equal subdivision, ring by ring (outer, then
/// holes in order) in input order along each ring, so polygon vertex j of a ring is node
/// (pieces of the earlier rings) + Σ_{i<j} ⌈len_i/h⌉. Never panics: a panic inside spade
/// (none is known; it would be a bug there) is caught and returned as
/// [`PolygonError::MeshingFailed`], though the panic hook still prints it.
pub fn triangulate(
    outer: &[[f64; 2]],
    holes: &[Vec<[f64; 2]>],
    h: f64,
    max_nodes: usize,
) -> Result<Triangulation, PolygonError> {
    if !(h.is_finite() && h > 0.0) {
        return Err(PolygonError::InvalidSize { h });
    }
    let rings: Vec<(Ring, &[[f64; 2]])> = std::iter::once((Ring::Outer, outer))
        .chain(
            holes
                .iter()
                .enumerate()
                .map(|(i, hole)| (Ring::Hole(i), hole.as_slice())),
        )
        .collect();
    for &(ring, points) in &rings {
        check_vertices(ring, points)?;
    }
    let total: usize = rings.iter().map(|(_, p)| p.len()).sum();
    if total > max_nodes {
        return Err(PolygonError::TooManyNodes {
            h,
            at_least: total,
            max_nodes,
        });
    }

    // The input rings as they are: crossings, touching, containment.
    let input = Boundary::new(rings.iter().map(|&(ring, points)| {
        (0..points.len()).map(move |i| BoundaryNode {
            point: points[i],
            ring,
            edge: i,
            corner: true,
        })
    }));
    let cdt = input.load().map_err(|e| input.describe(e))?;
    for &(ring, points) in &rings {
        if signed_area(points) == 0.0 {
            return Err(PolygonError::ZeroArea { ring });
        }
    }
    check_nesting(&cdt, &input, &rings)?;

    // The size bound, before anything proportional to the mesh is allocated.
    let max_area = 3f64.sqrt() / 4.0 * h * h;
    let area = signed_area(outer).abs()
        - holes
            .iter()
            .map(|hole| signed_area(hole).abs())
            .sum::<f64>();
    let boundary_nodes: f64 = rings
        .iter()
        .flat_map(|&(_, points)| (0..points.len()).map(move |i| pieces(points, i, h)))
        .sum();
    let bound = (area.max(0.0) / max_area + boundary_nodes) / 2.0;
    if bound > max_nodes as f64 || boundary_nodes > max_nodes as f64 {
        return Err(PolygonError::TooManyNodes {
            h,
            // Saturating conversion; ceil so that the figure exceeds max_nodes.
            at_least: bound.max(boundary_nodes).ceil() as usize,
            max_nodes,
        });
    }

    // The subdivided boundary and its triangulation.
    let boundary = Boundary::new(rings.iter().map(|&(ring, points)| {
        (0..points.len()).flat_map(move |i| {
            let [p, q] = [points[i], points[(i + 1) % points.len()]];
            let n = pieces(points, i, h) as usize;
            (0..n).map(move |k| {
                let t = k as f64 / n as f64;
                BoundaryNode {
                    point: [p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])],
                    ring,
                    edge: i,
                    corner: k == 0,
                }
            })
        })
    }));
    // Refinement keeping the boundary pieces; if that leaves triangles worse than the
    // geometry explains, again from scratch letting refinement split boundary pieces.
    let limits = Limits {
        max_area,
        max_nodes,
        h,
    };
    let kept = refine(&boundary, &limits, true)?;
    let sharp = sharp_corners(&rings);
    let sharp_nodes: Vec<bool> = boundary
        .nodes
        .iter()
        .map(|n| n.corner && sharp[ring_index(n.ring)][n.edge])
        .collect();
    if acceptable(&kept, h, &sharp_nodes) {
        return Ok(kept);
    }
    refine(&boundary, &limits, false)
}

struct Limits {
    max_area: f64,
    max_nodes: usize,
    h: f64,
}

/// The triangulation of `boundary` refined to the limits, boundary pieces kept or not.
fn refine(boundary: &Boundary, limits: &Limits, keep: bool) -> Result<Triangulation, PolygonError> {
    let mut cdt = boundary.load().map_err(|e| match e {
        LoadError::Meet { edge, .. } => {
            let node = &boundary.nodes[edge];
            PolygonError::BoundaryTooClose {
                ring: node.ring,
                edge: node.edge,
            }
        }
        LoadError::Spade(reason) => PolygonError::MeshingFailed { reason },
    })?;
    // Capped so that completing means at most max_nodes vertices. The ratio 1 of
    // circumradius to shortest edge is exactly the 30° bound (no sine of a rounded angle).
    let mut params = RefinementParameters::<f64>::new()
        .exclude_outer_faces(true)
        .with_angle_limit(AngleLimit::from_radius_to_shortest_edge_ratio(1.0))
        .with_max_allowed_area(limits.max_area)
        .with_max_additional_vertices(
            limits
                .max_nodes
                .saturating_add(1)
                .saturating_sub(cdt.num_vertices()),
        );
    if keep {
        params = params.keep_constraint_edges();
    }
    let complete = guarded(|| cdt.refine(params).refinement_complete)
        .map_err(|reason| PolygonError::MeshingFailed { reason })?;
    if !complete {
        return Err(PolygonError::TooManyNodes {
            h: limits.h,
            at_least: limits.max_nodes.saturating_add(1),
            max_nodes: limits.max_nodes,
        });
    }
    Ok(extract(&cdt))
}

/// cos 20°: the smallest angle accepted from the refinement that keeps the boundary pieces,
/// except in triangles at a sharp polygon corner.
const COS_ACCEPTED_ANGLE: f64 = 0.939_692_620_785_908_4;

/// cos 40°: polygon corners with a smaller angle (on the domain's side) are sharp; a triangle
/// there cannot have all its angles above 20°.
const COS_SHARP_CORNER: f64 = 0.766_044_443_118_978;

fn ring_index(ring: Ring) -> usize {
    match ring {
        Ring::Outer => 0,
        Ring::Hole(i) => i + 1,
    }
}

/// For every vertex of every ring: whether the domain's angle there is below 40°.
fn sharp_corners(rings: &[(Ring, &[[f64; 2]])]) -> Vec<Vec<bool>> {
    rings
        .iter()
        .map(|&(ring, points)| {
            // Traversed with the domain on the left: the outer ring counter-clockwise, holes
            // clockwise.
            let left = (signed_area(points) > 0.0) == (ring == Ring::Outer);
            let n = points.len();
            (0..n)
                .map(|i| {
                    let (a, b, c) = (points[(i + n - 1) % n], points[i], points[(i + 1) % n]);
                    let turn = orient(a, b, c);
                    turn != 0.0 && (turn > 0.0) == left && angle_cos(b, a, c) > COS_SHARP_CORNER
                })
                .collect()
        })
        .collect()
}

/// The cosine of the angle at `b` between the rays to `a` and `c`.
fn angle_cos(b: [f64; 2], a: [f64; 2], c: [f64; 2]) -> f64 {
    let u = [a[0] - b[0], a[1] - b[1]];
    let v = [c[0] - b[0], c[1] - b[1]];
    let dot = u[0] * v[0] + u[1] * v[1];
    dot / ((u[0] * u[0] + u[1] * u[1]).sqrt() * (v[0] * v[0] + v[1] * v[1]).sqrt())
}

/// Whether a mesh refined with the boundary pieces kept is good enough: every edge at most
/// 1.5 h, and every angle at least 20° except in triangles at a sharp polygon corner
/// (`sharp[i]` for the first nodes, the boundary ones). Cosines and square roots only, so the
/// decision is the same on every machine.
fn acceptable(mesh: &Triangulation, h: f64, sharp: &[bool]) -> bool {
    let max_edge2 = (1.5 * h) * (1.5 * h);
    mesh.triangles.iter().all(|t| {
        let p = t.map(|i| mesh.nodes[i]);
        let at_sharp_corner = t.iter().any(|&i| sharp.get(i) == Some(&true));
        (0..3).all(|k| {
            let (a, b, c) = (p[(k + 2) % 3], p[k], p[(k + 1) % 3]);
            let e = [c[0] - b[0], c[1] - b[1]];
            (at_sharp_corner || angle_cos(b, a, c) <= COS_ACCEPTED_ANGLE)
                && e[0] * e[0] + e[1] * e[1] <= max_edge2
        })
    })
}

/// Runs spade code, turning a panic (an internal failure, e.g. a circumcentre that cannot be
/// represented) into an error.
fn guarded<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).map_err(|payload| {
        payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "internal error".to_string())
    })
}

fn check_vertices(ring: Ring, points: &[[f64; 2]]) -> Result<(), PolygonError> {
    if points.len() < 3 {
        return Err(PolygonError::TooFewVertices {
            ring,
            count: points.len(),
        });
    }
    for (vertex, p) in points.iter().enumerate() {
        if !(p[0].is_finite() && p[1].is_finite()) {
            return Err(PolygonError::NonFiniteCoordinate { ring, vertex });
        }
        for value in *p {
            if value != 0.0 && !(MIN_COORDINATE..=MAX_COORDINATE).contains(&value.abs()) {
                return Err(PolygonError::CoordinateOutOfRange {
                    ring,
                    vertex,
                    value,
                });
            }
        }
    }
    for vertex in 0..points.len() {
        let next = (vertex + 1) % points.len();
        if points[vertex] == points[next] {
            return Err(PolygonError::RepeatedVertex { ring, vertex, next });
        }
    }
    Ok(())
}

/// The signed area (positive counter-clockwise), summed about the first vertex.
fn signed_area(points: &[[f64; 2]]) -> f64 {
    let o = points[0];
    let mut twice = 0.0;
    for i in 1..points.len().saturating_sub(1) {
        let (a, b) = (points[i], points[i + 1]);
        twice += (a[0] - o[0]) * (b[1] - o[1]) - (b[0] - o[0]) * (a[1] - o[1]);
    }
    twice / 2.0
}

/// ⌈length/h⌉ (at least 1) pieces of edge `i` of a ring, as a float (it may be huge).
fn pieces(points: &[[f64; 2]], i: usize, h: f64) -> f64 {
    let [p, q] = [points[i], points[(i + 1) % points.len()]];
    let (dx, dy) = (q[0] - p[0], q[1] - p[1]);
    ((dx * dx + dy * dy).sqrt() / h).ceil().max(1.0)
}

/// A node of a (possibly subdivided) ring and the polygon edge it starts a piece of.
struct BoundaryNode {
    point: [f64; 2],
    ring: Ring,
    /// Index of the polygon edge (its first vertex) on which the node lies.
    edge: usize,
    /// Whether the node is that first vertex.
    corner: bool,
}

/// Closed rings of nodes, stored one after the other; `starts[r]..starts[r + 1]` is ring r.
struct Boundary {
    nodes: Vec<BoundaryNode>,
    starts: Vec<usize>,
}

/// Why a boundary could not be loaded: segment `edge` (by its first node) meets segment
/// `other` (None if the exact scan found no partner), or spade failed.
enum LoadError {
    Meet { edge: usize, other: Option<usize> },
    Spade(String),
}

impl Boundary {
    fn new<R: IntoIterator<Item = BoundaryNode>>(rings: impl Iterator<Item = R>) -> Boundary {
        let mut nodes = Vec::new();
        let mut starts = vec![0];
        for ring in rings {
            nodes.extend(ring);
            starts.push(nodes.len());
        }
        Boundary { nodes, starts }
    }

    /// The node after node `i` along its ring.
    fn next(&self, i: usize) -> usize {
        let r = self.starts.partition_point(|&s| s <= i) - 1;
        if i + 1 == self.starts[r + 1] {
            self.starts[r]
        } else {
            i + 1
        }
    }

    fn point(&self, i: usize) -> Point2<f64> {
        let p = self.nodes[i].point;
        Point2::new(p[0], p[1])
    }

    /// The constrained Delaunay triangulation with one constraint edge per segment, vertex
    /// `i` being node `i`; an error if two segments meet anywhere but at the common node of
    /// consecutive segments.
    fn load(&self) -> Result<Cdt, LoadError> {
        // Equal positions first: spade would merge them and renumber the rest. Adding 0.0
        // turns -0.0 into 0.0, which spade takes for the same coordinate.
        let mut keys: Vec<(u64, u64, usize)> = self
            .nodes
            .iter()
            .enumerate()
            .map(|(i, n)| {
                (
                    (n.point[0] + 0.0).to_bits(),
                    (n.point[1] + 0.0).to_bits(),
                    i,
                )
            })
            .collect();
        keys.sort_unstable();
        let dup = keys
            .windows(2)
            .filter(|w| (w[0].0, w[0].1) == (w[1].0, w[1].1))
            .map(|w| (w[0].2, w[1].2))
            .min();
        if let Some((a, b)) = dup {
            // Node a coincides with node b: the segment starting at a touches the one at b.
            return Err(LoadError::Meet {
                edge: a,
                other: Some(b),
            });
        }
        let vertices: Vec<Point2<f64>> = (0..self.nodes.len()).map(|i| self.point(i)).collect();
        let edges: Vec<[usize; 2]> = (0..self.nodes.len()).map(|i| [i, self.next(i)]).collect();
        let cdt = guarded(|| Cdt::try_bulk_load_cdt(vertices, edges, |_| {}))
            .map_err(LoadError::Spade)?
            .map_err(|e| LoadError::Spade(format!("{e:?}")))?;
        let missing = (0..self.nodes.len()).find(|&i| {
            let [a, b] = [i, self.next(i)].map(FixedVertexHandle::from_index);
            !cdt.exists_constraint(a, b)
        });
        if let Some(edge) = missing {
            return Err(LoadError::Meet {
                edge,
                other: self.partner(edge),
            });
        }
        Ok(cdt)
    }

    /// The first segment that meets segment `s` other than at a shared end node (exact).
    fn partner(&self, s: usize) -> Option<usize> {
        let (a, b) = (self.nodes[s].point, self.nodes[self.next(s)].point);
        (0..self.nodes.len()).find(|&t| {
            if t == s {
                return false;
            }
            let t1 = self.next(t);
            let (c, d) = (self.nodes[t].point, self.nodes[t1].point);
            if t1 == s && self.next(s) == t {
                // A ring of two segments (cannot happen: rings have ≥ 3 nodes).
                return true;
            }
            if t1 == s {
                // t ends where s starts: they meet elsewhere only if d..c folds back on a..b.
                return folds_back(a, b, c);
            }
            if self.next(s) == t {
                return folds_back(b, a, d);
            }
            segments_meet(a, b, c, d)
        })
    }

    /// The error for a failed load of the input rings.
    fn describe(&self, e: LoadError) -> PolygonError {
        match e {
            LoadError::Spade(reason) => PolygonError::MeshingFailed { reason },
            LoadError::Meet { edge, other } => {
                let n = &self.nodes[edge];
                let Some(other) = other else {
                    return PolygonError::MeshingFailed {
                        reason: format!(
                            "the edge from vertex {} of {} could not be inserted",
                            n.edge, n.ring
                        ),
                    };
                };
                let m = &self.nodes[other];
                let ((ring, edge), (other_ring, other_edge)) =
                    if (n.ring, n.edge) <= (m.ring, m.edge) {
                        ((n.ring, n.edge), (m.ring, m.edge))
                    } else {
                        ((m.ring, m.edge), (n.ring, n.edge))
                    };
                if ring == other_ring {
                    PolygonError::SelfIntersecting {
                        ring,
                        edge,
                        other_edge,
                    }
                } else {
                    PolygonError::RingsIntersect {
                        ring,
                        edge,
                        other_ring,
                        other_edge,
                    }
                }
            }
        }
    }
}

fn orient(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    let coord = |p: [f64; 2]| robust::Coord { x: p[0], y: p[1] };
    robust::orient2d(coord(a), coord(b), coord(c))
}

/// Whether the closed segments ab and cd share a point (exact).
fn segments_meet(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    let (o1, o2) = (orient(a, b, c), orient(a, b, d));
    let (o3, o4) = (orient(c, d, a), orient(c, d, b));
    if o1 * o2 < 0.0 && o3 * o4 < 0.0 {
        return true;
    }
    (o1 == 0.0 && within(a, b, c))
        || (o2 == 0.0 && within(a, b, d))
        || (o3 == 0.0 && within(c, d, a))
        || (o4 == 0.0 && within(c, d, b))
}

/// For p collinear with ab: whether p lies on the closed segment ab.
fn within(a: [f64; 2], b: [f64; 2], p: [f64; 2]) -> bool {
    (0..2).all(|k| a[k].min(b[k]) <= p[k] && p[k] <= a[k].max(b[k]))
}

/// Segments ab and ca share the end a: whether c lies on the ray from a through b, so that
/// the two overlap.
fn folds_back(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> bool {
    orient(a, b, c) == 0.0 && (b[0] - a[0]) * (c[0] - a[0]) + (b[1] - a[1]) * (c[1] - a[1]) > 0.0
}

/// For every face (by spade's face index, the outer face being 0): the least number of
/// constraint edges a path from the outer face must cross to reach it.
fn crossings(cdt: &Cdt) -> Vec<u32> {
    let mut depth = vec![u32::MAX; cdt.num_all_faces()];
    let mut queue = VecDeque::new();
    depth[0] = 0;
    for edge in cdt.convex_hull() {
        let inside = edge.rev();
        if let Some(face) = inside.face().as_inner() {
            let d = u32::from(inside.is_constraint_edge());
            let f = face.fix().index();
            if d < depth[f] {
                depth[f] = d;
                if d == 0 {
                    queue.push_front(f);
                } else {
                    queue.push_back(f);
                }
            }
        }
    }
    let faces: Vec<_> = cdt.inner_faces().collect();
    // Inner faces by index: spade's inner face iterator starts at index 1.
    let mut by_index = vec![None; cdt.num_all_faces()];
    for face in faces {
        by_index[face.fix().index()] = Some(face);
    }
    while let Some(f) = queue.pop_front() {
        let Some(face) = by_index[f] else { continue };
        for edge in face.adjacent_edges() {
            let Some(neighbour) = edge.rev().face().as_inner() else {
                continue;
            };
            let n = neighbour.fix().index();
            let d = depth[f] + u32::from(edge.is_constraint_edge());
            if d < depth[n] {
                depth[n] = d;
                if d == depth[f] {
                    queue.push_front(n);
                } else {
                    queue.push_back(n);
                }
            }
        }
    }
    depth
}

/// Holes inside the outer ring and outside each other (rings known to be simple and
/// disjoint).
fn check_nesting(
    cdt: &Cdt,
    input: &Boundary,
    rings: &[(Ring, &[[f64; 2]])],
) -> Result<(), PolygonError> {
    let depth = crossings(cdt);
    // The number of rings enclosing ring r: the lesser depth on the two sides of an edge.
    let level = |r: usize| {
        let [a, b] = [input.starts[r], input.starts[r] + 1].map(FixedVertexHandle::from_index);
        cdt.get_edge_from_neighbors(a, b).map(|e| {
            let side = |f: Option<usize>| f.map_or(0, |f| depth[f]);
            let left = side(e.face().as_inner().map(|f| f.fix().index()));
            let right = side(e.rev().face().as_inner().map(|f| f.fix().index()));
            left.min(right)
        })
    };
    for (r, &(ring, points)) in rings.iter().enumerate().skip(1) {
        let Ring::Hole(hole) = ring else { continue };
        match level(r) {
            Some(1) => {}
            Some(0) => return Err(PolygonError::HoleOutside { hole }),
            Some(_) => {
                let container = rings
                    .iter()
                    .skip(1)
                    .enumerate()
                    .find(|&(other, (_, ring))| other != hole && encloses(ring, points[0]))
                    .map(|(other, _)| other);
                return Err(match container {
                    Some(container) => PolygonError::HolesNested { hole, container },
                    None => PolygonError::HoleOutside { hole },
                });
            }
            None => {
                return Err(PolygonError::MeshingFailed {
                    reason: format!("the first edge of {ring} is not in the triangulation"),
                })
            }
        }
    }
    if level(0) != Some(0) {
        return Err(PolygonError::MeshingFailed {
            reason: "the outer boundary is enclosed by another ring".to_string(),
        });
    }
    Ok(())
}

/// Whether point p (not on the ring) is inside the ring: exact winding number.
fn encloses(ring: &[[f64; 2]], p: [f64; 2]) -> bool {
    let mut winding = 0i64;
    for i in 0..ring.len() {
        let (a, b) = (ring[i], ring[(i + 1) % ring.len()]);
        if a[1] <= p[1] {
            if b[1] > p[1] && orient(a, b, p) > 0.0 {
                winding += 1;
            }
        } else if b[1] <= p[1] && orient(a, b, p) < 0.0 {
            winding -= 1;
        }
    }
    winding != 0
}

/// The faces enclosed by exactly one ring, with the used vertices renumbered in spade's order.
fn extract(cdt: &Cdt) -> Triangulation {
    let depth = crossings(cdt);
    let mut triangles: Vec<[usize; 3]> = cdt
        .inner_faces()
        .filter(|face| depth[face.fix().index()] == 1)
        .map(|face| face.vertices().map(|v| v.fix().index()))
        .collect();
    let mut used = vec![false; cdt.num_vertices()];
    for t in &triangles {
        for &v in t {
            used[v] = true;
        }
    }
    let mut new_index = vec![usize::MAX; cdt.num_vertices()];
    let mut nodes = Vec::new();
    for v in (0..used.len()).filter(|&v| used[v]) {
        new_index[v] = nodes.len();
        let p = cdt.vertex(FixedVertexHandle::from_index(v)).position();
        nodes.push([p.x, p.y]);
    }
    for t in &mut triangles {
        let m = t.map(|v| new_index[v]);
        let first = (0..3).min_by_key(|&k| m[k]).unwrap_or(0);
        *t = [m[first], m[(first + 1) % 3], m[(first + 2) % 3]];
    }
    triangles.sort_unstable();
    Triangulation { nodes, triangles }
}
