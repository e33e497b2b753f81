use super::*;
use proptest::prelude::*;
use sha2::{Digest, Sha256};
use std::collections::HashMap;

type P = [f64; 2];

fn l_shape() -> Vec<P> {
    vec![
        [0.0, 0.0],
        [2.0, 0.0],
        [2.0, 1.0],
        [1.0, 1.0],
        [1.0, 2.0],
        [0.0, 2.0],
    ]
}

fn unit_square() -> Vec<P> {
    vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]
}

/// Off-centre, clockwise (the other orientation is tested through the L and the trapezoid).
fn square_hole() -> Vec<P> {
    vec![[0.2, 0.3], [0.2, 0.6], [0.55, 0.6], [0.55, 0.3]]
}

fn trapezoid() -> Vec<P> {
    vec![[0.0, 0.0], [3.0, 0.0], [2.2, 1.0], [0.5, 1.0]]
}

fn sub(a: P, b: P) -> P {
    [a[0] - b[0], a[1] - b[1]]
}

fn len(a: P, b: P) -> f64 {
    let d = sub(b, a);
    (d[0] * d[0] + d[1] * d[1]).sqrt()
}

fn cross(u: P, v: P) -> f64 {
    u[0] * v[1] - u[1] * v[0]
}

fn rings<'a>(outer: &'a [P], holes: &'a [Vec<P>]) -> impl Iterator<Item = &'a [P]> {
    std::iter::once(outer).chain(holes.iter().map(Vec::as_slice))
}

/// Distance from p to the segment ab.
fn distance_to_segment(p: P, a: P, b: P) -> f64 {
    let (d, w) = (sub(b, a), sub(p, a));
    let t = ((w[0] * d[0] + w[1] * d[1]) / (d[0] * d[0] + d[1] * d[1])).clamp(0.0, 1.0);
    len(p, [a[0] + t * d[0], a[1] + t * d[1]])
}

/// The smallest angle of the mesh, in degrees.
fn min_angle(t: &Triangulation) -> f64 {
    let mut min = 180.0f64;
    for tri in &t.triangles {
        let p = tri.map(|i| t.nodes[i]);
        for k in 0..3 {
            let cos = angle_cos(p[k], p[(k + 1) % 3], p[(k + 2) % 3]);
            min = min.min(cos.clamp(-1.0, 1.0).acos().to_degrees());
        }
    }
    min
}

fn max_edge(t: &Triangulation) -> f64 {
    t.triangles
        .iter()
        .flat_map(|tri| (0..3).map(move |k| (tri[k], tri[(k + 1) % 3])))
        .map(|(a, b)| len(t.nodes[a], t.nodes[b]))
        .fold(0.0, f64::max)
}

/// Edge (sorted end nodes) → how many triangles have it.
fn edge_counts(t: &Triangulation) -> HashMap<(usize, usize), usize> {
    let mut counts = HashMap::new();
    for tri in &t.triangles {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            *counts.entry((a.min(b), a.max(b))).or_insert(0) += 1;
        }
    }
    counts
}

/// The properties every mesh of a valid polygon has, whatever h: counter-clockwise
/// triangles, every node used, conforming (edges in 1 or 2 triangles, Euler characteristic
/// 1 − holes), area and perimeter of the polygon, polygon vertices among the nodes,
/// boundary edges on the rings.
fn check_mesh(outer: &[P], holes: &[Vec<P>], t: &Triangulation) {
    let scale = rings(outer, holes)
        .flatten()
        .flat_map(|p| p.iter())
        .fold(0.0f64, |m, c| m.max(c.abs()));
    let tol = 1e-12 * scale.max(1.0);
    let mut used = vec![false; t.nodes.len()];
    let mut area = 0.0;
    for tri in &t.triangles {
        let p = tri.map(|i| t.nodes[i]);
        let twice = cross(sub(p[1], p[0]), sub(p[2], p[0]));
        assert!(
            twice > 0.0,
            "triangle {tri:?} at {p:?} is not counter-clockwise"
        );
        area += twice / 2.0;
        assert!(tri[0] != tri[1] && tri[1] != tri[2] && tri[0] != tri[2]);
        for &i in tri {
            used[i] = true;
        }
    }
    assert!(used.iter().all(|&u| u), "a node is in no triangle");

    let polygon_area =
        signed_area(outer).abs() - holes.iter().map(|h| signed_area(h).abs()).sum::<f64>();
    assert!(
        (area - polygon_area).abs() <= 1e-12 * polygon_area,
        "mesh area {area} vs polygon area {polygon_area}"
    );

    let counts = edge_counts(t);
    assert!(
        counts.values().all(|&c| c == 1 || c == 2),
        "non-manifold edge"
    );
    let euler = t.nodes.len() as i64 - counts.len() as i64 + t.triangles.len() as i64;
    assert_eq!(euler, 1 - holes.len() as i64, "Euler characteristic");

    let mut boundary_length = 0.0;
    for (&(a, b), _) in counts.iter().filter(|(_, &c)| c == 1) {
        let (pa, pb) = (t.nodes[a], t.nodes[b]);
        boundary_length += len(pa, pb);
        let on_a_ring_edge = rings(outer, holes).any(|ring| {
            (0..ring.len()).any(|i| {
                let (p, q) = (ring[i], ring[(i + 1) % ring.len()]);
                distance_to_segment(pa, p, q) <= tol && distance_to_segment(pb, p, q) <= tol
            })
        });
        assert!(
            on_a_ring_edge,
            "boundary edge {pa:?}–{pb:?} is on no polygon edge"
        );
    }
    let perimeter: f64 = rings(outer, holes)
        .flat_map(|ring| (0..ring.len()).map(move |i| len(ring[i], ring[(i + 1) % ring.len()])))
        .sum();
    assert!(
        (boundary_length - perimeter).abs() <= 1e-12 * perimeter,
        "boundary length {boundary_length} vs perimeter {perimeter}"
    );

    for p in rings(outer, holes).flatten() {
        assert!(t.nodes.contains(p), "polygon vertex {p:?} is not a node");
    }
}

/// A named polygon: outer ring and holes.
type Case = (&'static str, Vec<P>, Vec<Vec<P>>);

fn cases() -> Vec<Case> {
    vec![
        ("L-shape", l_shape(), vec![]),
        ("square with hole", unit_square(), vec![square_hole()]),
        ("trapezoid", trapezoid(), vec![]),
    ]
}

#[test]
fn meshes_have_the_polygon_s_area_boundary_and_quality() {
    let mut worst_angle = 180.0f64;
    let mut worst_edge = 0.0f64;
    for (name, outer, holes) in cases() {
        for h in [0.3, 0.2, 0.1, 0.05, 0.025] {
            let t = triangulate(&outer, &holes, h, 100_000).unwrap();
            check_mesh(&outer, &holes, &t);
            let (angle, edge) = (min_angle(&t), max_edge(&t) / h);
            eprintln!(
                "{name}, h = {h}: {} nodes, {} triangles, min angle {angle:.2}°, max edge {edge:.3} h",
                t.nodes.len(),
                t.triangles.len()
            );
            worst_angle = worst_angle.min(angle);
            worst_edge = worst_edge.max(edge);
        }
    }
    // 30° is requested; keeping the boundary pieces costs a little next to them.
    assert!(worst_angle >= 27.0, "min angle {worst_angle}°");
    assert!(worst_edge <= 1.5, "max edge {worst_edge} h");
}

#[test]
fn either_orientation_gives_a_valid_mesh() {
    let mut outer = l_shape();
    outer.reverse();
    let mut hole = square_hole();
    hole.reverse();
    let holes = vec![[[0.1, 1.2], [0.6, 1.2], [0.6, 1.6]].to_vec(), hole];
    let t = triangulate(&outer, &holes, 0.1, 100_000).unwrap();
    check_mesh(&outer, &holes, &t);
}

#[test]
fn boundary_nodes_come_first_in_ring_order_equally_spaced() {
    let (outer, holes) = (unit_square(), vec![square_hole()]);
    let h = 0.15;
    let t = triangulate(&outer, &holes, h, 100_000).unwrap();
    let mut next = 0;
    for ring in rings(&outer, &holes) {
        for i in 0..ring.len() {
            let (p, q) = (ring[i], ring[(i + 1) % ring.len()]);
            let n = (len(p, q) / h).ceil() as usize;
            assert_eq!(t.nodes[next], p, "polygon vertex at node {next}");
            for k in 1..n {
                let expected = [
                    p[0] + k as f64 / n as f64 * (q[0] - p[0]),
                    p[1] + k as f64 / n as f64 * (q[1] - p[1]),
                ];
                assert_eq!(t.nodes[next + k], expected);
            }
            next += n;
        }
    }
    // This mesh kept every boundary piece: the boundary nodes are exactly those.
    let on_boundary: usize = edge_counts(&t).values().filter(|&&c| c == 1).count();
    assert_eq!(on_boundary, next);
}

/// Outputs are compared bit for bit, and against a fingerprint: a change of it (a spade
/// upgrade that refines differently, a change here) must be deliberate.
#[test]
fn output_is_deterministic() {
    let fingerprint = |t: &Triangulation| {
        let mut hash = Sha256::new();
        for p in &t.nodes {
            hash.update(p[0].to_bits().to_le_bytes());
            hash.update(p[1].to_bits().to_le_bytes());
        }
        for tri in &t.triangles {
            for &i in tri {
                hash.update((i as u64).to_le_bytes());
            }
        }
        hash.finalize()
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect::<String>()
    };
    let (outer, holes) = (unit_square(), vec![square_hole()]);
    let a = triangulate(&outer, &holes, 0.05, 100_000).unwrap();
    let b = triangulate(&outer, &holes, 0.05, 100_000).unwrap();
    assert_eq!(fingerprint(&a), fingerprint(&b));
    assert_eq!(a, b);
    assert_eq!((a.nodes.len(), a.triangles.len()), (699, 1292));
    assert_eq!(
        fingerprint(&a),
        "d738d0898db57a58cfee03436141e5cd0801e9151c89654303290c50642c5eb3"
    );
}

#[test]
fn halving_h_about_quadruples_the_cells() {
    for (name, outer, holes) in cases() {
        let coarse = triangulate(&outer, &holes, 0.1, 100_000).unwrap();
        let fine = triangulate(&outer, &holes, 0.05, 100_000).unwrap();
        let ratio = fine.triangles.len() as f64 / coarse.triangles.len() as f64;
        assert!((3.5..=4.5).contains(&ratio), "{name}: ratio {ratio}");
    }
}

#[test]
fn features_finer_than_h_are_resolved_by_splitting_boundary_pieces() {
    // A strip a tenth of h wide and a step a hundredth of h high: keeping the pieces of
    // length h would leave needles, so the refinement splits them.
    let strip = vec![[0.0, 0.0], [1.0, 0.0], [1.0, 0.01], [0.0, 0.01]];
    let step = vec![
        [0.0, 0.0],
        [1.0, 0.0],
        [1.0, 0.5],
        [0.51, 0.5],
        [0.5, 0.501],
        [0.0, 0.501],
    ];
    for outer in [strip, step] {
        let t = triangulate(&outer, &[], 0.1, 100_000).unwrap();
        check_mesh(&outer, &[], &t);
        assert!(min_angle(&t) >= 25.0, "min angle {}", min_angle(&t));
        assert!(max_edge(&t) <= 0.15);
    }
    // A sharp corner of the polygon bounds the angles: the mesh keeps it and is accepted.
    let sharp = vec![[0.0, 0.0], [1.0, 0.0], [1.0, 0.176]];
    let t = triangulate(&sharp, &[], 0.1, 100_000).unwrap();
    check_mesh(&sharp, &[], &t);
    assert!(min_angle(&t) >= 9.9);
}

fn err(outer: &[P], holes: &[Vec<P>], h: f64, max_nodes: usize) -> PolygonError {
    match triangulate(outer, holes, h, max_nodes) {
        Ok(t) => panic!("meshed into {} triangles", t.triangles.len()),
        Err(e) => e,
    }
}

fn square_at(x: f64, y: f64, side: f64) -> Vec<P> {
    vec![[x, y], [x + side, y], [x + side, y + side], [x, y + side]]
}

#[test]
fn invalid_sizes_are_refused() {
    for h in [0.0, -0.1, f64::NAN, f64::INFINITY] {
        let e = err(&unit_square(), &[], h, 1000);
        assert!(matches!(e, PolygonError::InvalidSize { .. }), "{e:?}");
    }
}

#[test]
fn malformed_rings_are_refused() {
    use PolygonError::*;
    let hole = square_at(0.4, 0.4, 0.2);
    assert_eq!(
        err(&[[0.0, 0.0], [1.0, 0.0]], &[], 0.1, 1000),
        TooFewVertices {
            ring: Ring::Outer,
            count: 2
        }
    );
    assert_eq!(
        err(&unit_square(), &[hole.clone(), vec![]], 0.1, 1000),
        TooFewVertices {
            ring: Ring::Hole(1),
            count: 0
        }
    );
    let mut nan = hole.clone();
    nan[2][1] = f64::NAN;
    assert_eq!(
        err(&unit_square(), &[nan], 0.1, 1000),
        NonFiniteCoordinate {
            ring: Ring::Hole(0),
            vertex: 2
        }
    );
    for value in [1e31, -1e-40, f64::MIN_POSITIVE] {
        let mut far = unit_square();
        far[1][0] = value;
        assert_eq!(
            err(&far, &[], 0.1, 1000),
            CoordinateOutOfRange {
                ring: Ring::Outer,
                vertex: 1,
                value
            }
        );
    }
    let mut repeated = unit_square();
    repeated.insert(2, repeated[2]);
    assert_eq!(
        err(&repeated, &[], 0.1, 1000),
        RepeatedVertex {
            ring: Ring::Outer,
            vertex: 2,
            next: 3
        }
    );
    let mut closed = hole.clone();
    closed.push(closed[0]);
    assert_eq!(
        err(&unit_square(), &[closed], 0.1, 1000),
        RepeatedVertex {
            ring: Ring::Hole(0),
            vertex: 4,
            next: 0
        }
    );
    // Not collinear in exact arithmetic (the cross product is 2⁻¹⁰⁴), but its area rounds
    // to 0.
    let e = f64::EPSILON;
    assert_eq!(
        err(
            &[[0.0, 0.0], [1.0 + e, 1.0], [1.0 + 2.0 * e, 1.0 + e]],
            &[],
            0.1,
            1000
        ),
        ZeroArea { ring: Ring::Outer }
    );
}

#[test]
fn intersecting_rings_are_refused() {
    use PolygonError::*;
    let bowtie = vec![[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]];
    assert_eq!(
        err(&bowtie, &[], 0.1, 1000),
        SelfIntersecting {
            ring: Ring::Outer,
            edge: 0,
            other_edge: 2
        }
    );
    let collinear = vec![[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]];
    assert!(matches!(
        err(&collinear, &[], 0.1, 1000),
        SelfIntersecting {
            ring: Ring::Outer,
            ..
        }
    ));
    // Vertex 4 touches edge 1 (from (1, 0) to (1, 1)) of the same ring.
    let touching = vec![
        [0.0, 0.0],
        [1.0, 0.0],
        [1.0, 1.0],
        [0.5, 1.0],
        [1.0, 0.5],
        [0.0, 1.0],
    ];
    let e = err(&touching, &[], 0.1, 1000);
    assert!(
        matches!(
            e,
            SelfIntersecting {
                ring: Ring::Outer,
                edge: 1,
                other_edge: 3 | 4
            }
        ),
        "{e:?}"
    );
    // A hole crossing the outer boundary, one sharing a vertex with it, two holes crossing.
    let e = err(&unit_square(), &[square_at(0.8, 0.4, 0.4)], 0.1, 1000);
    assert!(
        matches!(
            e,
            RingsIntersect {
                ring: Ring::Outer,
                edge: 1,
                other_ring: Ring::Hole(0),
                ..
            }
        ),
        "{e:?}"
    );
    let e = err(
        &unit_square(),
        &[vec![[1.0, 1.0], [0.5, 0.8], [0.8, 0.5]]],
        0.1,
        1000,
    );
    assert!(
        matches!(
            e,
            RingsIntersect {
                ring: Ring::Outer,
                edge: 1 | 2,
                other_ring: Ring::Hole(0),
                other_edge: 0 | 2
            }
        ),
        "{e:?}"
    );
    let e = err(
        &unit_square(),
        &[square_at(0.1, 0.1, 0.3), square_at(0.3, 0.3, 0.3)],
        0.1,
        1000,
    );
    assert!(
        matches!(
            e,
            RingsIntersect {
                ring: Ring::Hole(0),
                other_ring: Ring::Hole(1),
                ..
            }
        ),
        "{e:?}"
    );
    // Overlapping edges on a common line.
    let e = err(&unit_square(), &[square_at(0.2, 0.0, 0.3)], 0.1, 1000);
    assert!(matches!(e, RingsIntersect { .. }), "{e:?}");
}

#[test]
fn misplaced_holes_are_refused() {
    use PolygonError::*;
    assert_eq!(
        err(
            &unit_square(),
            &[square_at(0.1, 0.1, 0.2), square_at(2.0, 0.0, 0.5)],
            0.1,
            1000
        ),
        HoleOutside { hole: 1 }
    );
    // The outer boundary inside a hole: the hole is not inside it.
    assert_eq!(
        err(&unit_square(), &[square_at(-1.0, -1.0, 3.0)], 0.1, 1000),
        HoleOutside { hole: 0 }
    );
    assert_eq!(
        err(
            &unit_square(),
            &[square_at(0.3, 0.3, 0.1), square_at(0.2, 0.2, 0.5)],
            0.1,
            1000
        ),
        HolesNested {
            hole: 0,
            container: 1
        }
    );
}

#[test]
fn meshes_above_max_nodes_are_refused() {
    // By the estimate before meshing: (1/(√3/4·10⁻⁶) + 4000)/2 ≈ 1.16e6 nodes.
    let e = err(&unit_square(), &[], 1e-3, 1_000_000);
    assert!(
        matches!(e, PolygonError::TooManyNodes { at_least, max_nodes: 1_000_000, .. } if at_least > 1_000_000),
        "{e:?}"
    );
    // Hostile: h so small that the estimate overflows any count.
    let e = err(&unit_square(), &[], 1e-200, usize::MAX);
    assert!(matches!(e, PolygonError::TooManyNodes { .. }), "{e:?}");
    // More polygon vertices than allowed nodes.
    let e = err(&unit_square(), &[], 0.5, 3);
    assert!(
        matches!(e, PolygonError::TooManyNodes { at_least: 4, .. }),
        "{e:?}"
    );
    // Past the estimate (≈ 135 nodes at h = 0.1) but not the refinement's cap: stopped there.
    let needed = triangulate(&unit_square(), &[], 0.1, 100_000)
        .unwrap()
        .nodes
        .len();
    assert!(needed > 150);
    assert_eq!(
        err(&unit_square(), &[], 0.1, 150),
        PolygonError::TooManyNodes {
            h: 0.1,
            at_least: 151,
            max_nodes: 150
        }
    );
    assert_eq!(
        triangulate(&unit_square(), &[], 0.1, needed)
            .unwrap()
            .nodes
            .len(),
        needed
    );
}

#[test]
fn rings_closer_than_the_subdivision_can_resolve_are_refused() {
    // A slanted outer edge cut into n pieces: some subdivision point rounds off the exact
    // line to the inside. A hole with a vertex exactly there is valid input (it does not
    // touch the edge) but coincides with a boundary node.
    let outer = vec![[0.0, 0.0], [0.7, 0.3], [0.7, 1.0], [0.0, 1.0]];
    let (p, q) = (outer[0], outer[1]);
    let (n, inside) = (3..100)
        .flat_map(|n| (1..n).map(move |k| (n, k)))
        .map(|(n, k)| {
            let t = k as f64 / n as f64;
            (n, [p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])])
        })
        .find(|&(_, x)| x[0] > 0.2 && orient(p, q, x) > 0.0)
        .expect("a subdivision point off the line, inside");
    let h = len(p, q) / (n as f64 - 0.5);
    let hole = vec![inside, [inside[0], 0.6], [inside[0] - 0.1, 0.6]];
    let e = err(&outer, &[hole], h, 100_000);
    assert_eq!(
        e,
        PolygonError::BoundaryTooClose {
            ring: Ring::Outer,
            edge: 0
        }
    );
}

#[test]
fn errors_are_sentences_naming_ring_and_vertex() {
    let e = err(
        &unit_square(),
        &[
            square_at(0.1, 0.1, 0.2),
            vec![[0.5, 0.5], [0.6, 0.5], [0.6, 0.5]],
        ],
        0.1,
        1000,
    );
    assert_eq!(
        e.to_string(),
        "vertices 1 and 2 of hole 1 are the same point (list each corner once, without \
         repeating the first vertex at the end)"
    );
    let e = err(
        &[[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]],
        &[],
        0.1,
        1000,
    );
    assert_eq!(
        e.to_string(),
        "the outer boundary intersects itself: its edge from vertex 0 crosses or touches its \
         edge from vertex 2"
    );
    let e = err(&unit_square(), &[square_at(0.8, 0.4, 0.4)], 0.1, 1000);
    assert_eq!(
        e.to_string(),
        "the outer boundary and hole 0 intersect: edge 1 of the outer boundary crosses or \
         touches edge 0 of hole 0"
    );
    let e = err(&unit_square(), &[], 1e-3, 1000);
    assert_eq!(
        e.to_string(),
        "the mesh at h = 0.001 would have at least 1156701 nodes, more than the limit of 1000; \
         choose a larger h"
    );
}

/// Whether a polygon error means a panic was caught inside spade (none should be).
fn is_internal(e: &PolygonError) -> bool {
    matches!(e, PolygonError::MeshingFailed { .. })
}

/// Coordinates in [lo, hi]: from a coarse grid (many collinear and coincident points), any,
/// or now and then hostile values.
fn coordinate(lo: f64, hi: f64) -> impl Strategy<Value = f64> {
    prop_oneof![
        10 => (0i32..5).prop_map(move |i| lo + (hi - lo) * i as f64 / 4.0),
        10 => lo..hi,
        1 => prop_oneof![Just(f64::NAN), Just(-0.0), Just(1e-35), Just(1e29), Just(f64::INFINITY)],
    ]
}

/// Mostly 3 to 8 vertices, sometimes fewer.
fn ring(lo: f64, hi: f64) -> impl Strategy<Value = Vec<P>> {
    let point = move || [coordinate(lo, hi), coordinate(lo, hi)];
    prop_oneof![
        8 => prop::collection::vec(point(), 3..9),
        1 => prop::collection::vec(point(), 0..3),
    ]
}

/// A star-shaped polygon about `c`: always simple.
fn star(c: P, radii: &[f64]) -> Vec<P> {
    let n = radii.len();
    radii
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let a = std::f64::consts::TAU * i as f64 / n as f64;
            [c[0] + r * a.cos(), c[1] + r * a.sin()]
        })
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1024))]

    /// Random point lists: an error or a valid mesh, never a panic (nor a caught one).
    #[test]
    fn random_point_lists_never_panic(
        outer in ring(-1.0, 2.0),
        holes in prop::collection::vec(ring(0.2, 0.8), 0..3),
        h in prop_oneof![Just(0.05), Just(0.3), 0.0f64..1.0, Just(1e-9)],
    ) {
        let r = triangulate(&outer, &holes, h, 20_000);
        match r {
            Ok(t) => check_mesh(&outer, &holes, &t),
            Err(e) => prop_assert!(!is_internal(&e), "{e}"),
        }
    }

    /// Random simple polygons with a hole: always meshed, with the polygon's area.
    #[test]
    fn random_star_polygons_are_meshed(
        radii in prop::collection::vec(0.5f64..1.0, 6..12),
        hole_radii in prop::collection::vec(0.1f64..0.2, 3..8),
        h in 0.05f64..0.5,
    ) {
        let outer = star([0.0, 0.0], &radii);
        let holes = vec![star([0.1, -0.1], &hole_radii)];
        let t = triangulate(&outer, &holes, h, 100_000).unwrap();
        check_mesh(&outer, &holes, &t);
    }
}
