use super::*;
use crate::mesh::MeshPattern;
use crate::solve::stepper::ContactNode;
use std::collections::{HashMap, HashSet};

/// The boxes the tests take apart: a cube and a box with three different sides and counts.
fn boxes() -> Vec<([f64; 3], [usize; 3])> {
    vec![([1.0; 3], [3, 3, 3]), ([2.0, 0.5, 1.5], [4, 2, 3])]
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Twice the area times the unit normal (counter-clockwise) of a triangle.
fn area_vector(p: [[f64; 3]; 3]) -> [f64; 3] {
    cross(sub(p[1], p[0]), sub(p[2], p[0]))
}

fn corners(s: &Surface, nodes: &[[f64; 3]], t: usize) -> [[f64; 3]; 3] {
    s.triangles[t].map(|n| nodes[n])
}

/// Counts from the box's lattice alone: two triangles per boundary square, and every node
/// but the (nx−1)(ny−1)(nz−1) interior ones.
#[test]
fn a_kuhn_box_has_the_lattice_counts_of_boundary_triangles_and_nodes() {
    for (_, [nx, ny, nz]) in boxes() {
        let m = Mesh::cuboid(1.0, 1.0, 1.0, nx, ny, nz);
        let s = Surface::of_solid(&m);
        assert_eq!(s.triangles.len(), 4 * (nx * ny + ny * nz + nz * nx));
        assert_eq!(s.cells.len(), s.triangles.len());
        let all = (nx + 1) * (ny + 1) * (nz + 1);
        let interior = (nx - 1) * (ny - 1) * (nz - 1);
        assert_eq!(s.node_ids.len(), all - interior);
    }
    // The cube of n cells a side: 12n² triangles on 6n² + 2 nodes.
    for n in 1..=5 {
        let s = Surface::of_solid(&Mesh::cuboid(1.0, 1.0, 1.0, n, n, n));
        assert_eq!(s.triangles.len(), 12 * n * n);
        assert_eq!(s.node_ids.len(), 6 * n * n + 2);
    }
}

#[test]
fn the_surface_is_closed_consistently_oriented_and_has_euler_characteristic_two() {
    for (l, n) in boxes() {
        let m = Mesh::cuboid(l[0], l[1], l[2], n[0], n[1], n[2]);
        let s = Surface::of_solid(&m);
        // Every directed edge once: each undirected edge is in exactly two triangles, which
        // run along it in opposite directions (one orientation over the whole surface).
        let mut directed = HashSet::new();
        let mut undirected: HashMap<(usize, usize), usize> = HashMap::new();
        for t in &s.triangles {
            assert!(t[0] != t[1] && t[1] != t[2] && t[0] != t[2]);
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                assert!(directed.insert((a, b)), "directed edge {a}→{b} twice");
                *undirected.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        assert!(undirected.values().all(|&c| c == 2));
        let (v, e, f) = (
            s.node_ids.len() as i64,
            undirected.len() as i64,
            s.triangles.len() as i64,
        );
        assert_eq!(v - e + f, 2);
        // Every surface node is used by a triangle.
        let used: HashSet<usize> = s.triangles.iter().flatten().copied().collect();
        assert_eq!(used.len(), s.node_ids.len());
    }
}

#[test]
fn area_is_the_boxs_and_the_divergence_theorem_gives_its_volume() {
    for (l, n) in boxes() {
        let m = Mesh::cuboid(l[0], l[1], l[2], n[0], n[1], n[2]);
        let s = Surface::of_solid(&m);
        let nodes = s.nodes(&m);
        let (mut area, mut volume) = (0.0, 0.0);
        for t in 0..s.triangles.len() {
            let p = corners(&s, &nodes, t);
            let a2 = area_vector(p);
            area += dot(a2, a2).sqrt() / 2.0;
            // ∫_F x·n dA = |F| n·centroid for a flat face; div x = 3.
            let centroid = [0, 1, 2].map(|c| (p[0][c] + p[1][c] + p[2][c]) / 3.0);
            volume += dot(a2, centroid) / 2.0 / 3.0;
        }
        let (lx, ly, lz) = (l[0], l[1], l[2]);
        assert!((area - 2.0 * (lx * ly + ly * lz + lz * lx)).abs() < 1e-12);
        assert!(
            (volume - lx * ly * lz).abs() < 1e-12,
            "volume {volume}: faces not outward"
        );
    }
}

#[test]
fn each_triangle_is_a_face_of_its_cell_and_points_away_from_the_cells_fourth_vertex() {
    for (l, n) in boxes() {
        let m = Mesh::cuboid(l[0], l[1], l[2], n[0], n[1], n[2]);
        let s = Surface::of_solid(&m);
        for (t, tri) in s.triangles.iter().enumerate() {
            let original = tri.map(|k| s.node_ids[k]);
            let cell = m.cell(s.cells[t]);
            assert!(original.iter().all(|n| cell.contains(n)));
            let fourth = *cell.iter().find(|n| !original.contains(n)).unwrap();
            let p = original.map(|k| m.nodes[k]);
            assert!(dot(area_vector(p), sub(m.nodes[fourth], p[0])) < 0.0);
        }
    }
}

#[test]
fn the_node_map_gives_the_original_coordinates_and_exactly_the_boundary_nodes() {
    for (l, n) in boxes() {
        let m = Mesh::cuboid(l[0], l[1], l[2], n[0], n[1], n[2]);
        let s = Surface::of_solid(&m);
        let nodes = s.nodes(&m);
        for (i, &id) in s.node_ids.iter().enumerate() {
            assert_eq!(nodes[i], m.nodes[id]);
            assert_eq!(s.index_of(id), Some(i));
        }
        assert!(s.node_ids.windows(2).all(|w| w[0] < w[1]));
        // The nodes on a face of the box, found from the coordinates.
        let on_boundary: Vec<usize> = (0..m.n_nodes())
            .filter(|&k| (0..3).any(|c| m.nodes[k][c] == 0.0 || m.nodes[k][c] == l[c]))
            .collect();
        assert_eq!(s.node_ids, on_boundary);
    }
}

/// The mesh's own boundary facets (found by the generator, outward by construction) are the
/// same triangles, turned the same way.
#[test]
fn the_triangles_are_the_meshs_boundary_facets_with_the_same_orientation() {
    let m = Mesh::cuboid(2.0, 0.5, 1.5, 4, 2, 3);
    let s = Surface::of_solid(&m);
    // A triangle up to rotation: its smallest node first.
    let canonical = |t: [usize; 3]| {
        let k = (0..3).min_by_key(|&k| t[k]).unwrap();
        [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
    };
    let ours: HashSet<[usize; 3]> = s
        .triangles
        .iter()
        .map(|t| canonical(t.map(|k| s.node_ids[k])))
        .collect();
    let theirs: HashSet<[usize; 3]> = m.facets.iter().map(|f| canonical(f.nodes)).collect();
    assert_eq!(ours, theirs);
    assert_eq!(s.parts(&m), vec![None; s.triangles.len()]);
}

/// Orientation is geometric: the same cells with the opposite vertex order give the same
/// surface.
#[test]
fn cells_of_either_orientation_give_the_same_surface() {
    let m = Mesh::cuboid(1.0, 1.0, 1.0, 2, 3, 2);
    let mut flipped = m.cells_flat().to_vec();
    for c in flipped.chunks_exact_mut(4) {
        c.swap(1, 2);
    }
    let mirrored = Mesh::from_cells(m.nodes.clone(), flipped).unwrap();
    let (a, b) = (Surface::of_solid(&m), Surface::of_solid(&mirrored));
    assert_eq!(a.node_ids, b.node_ids);
    assert_eq!(a.cells, b.cells);
    for (s, t) in a.triangles.iter().zip(&b.triangles) {
        let p = s.map(|k| m.nodes[a.node_ids[k]]);
        let q = t.map(|k| m.nodes[b.node_ids[k]]);
        let (n, o) = (area_vector(p), area_vector(q));
        assert!(dot(n, o) > 0.0);
    }
    // And the same again: the output does not depend on the hash map's order.
    assert_eq!(Surface::of_solid(&m), a);
}

#[test]
fn a_plane_mesh_has_no_surface() {
    let m = AnyMesh::Plane(Mesh::rectangle(1.0, 1.0, 2, 2, MeshPattern::Diagonal));
    assert!(Surface::of(&m).is_none());
    let solid = AnyMesh::Solid(Mesh::cuboid(1.0, 1.0, 1.0, 1, 1, 1));
    assert_eq!(Surface::of(&solid).unwrap().triangles.len(), 12);
}

/// Fields whose values name where they come from: u is the node's position, ζ its id, von
/// Mises and σ their cell's id.
fn labelled(m: &Mesh<3>) -> StepFields {
    let nc = m.n_cells();
    StepFields {
        n: 3,
        t: 0.75,
        u: Some(m.nodes.iter().flatten().copied().collect()),
        w: Some(m.nodes.iter().flatten().map(|x| -x).collect()),
        zeta: Some((0..m.n_nodes()).map(|k| k as f64).collect()),
        sigma: Some(Stress::Solid(
            (0..nc)
                .map(|e| [e as f64, 1.0, 2.0, 3.0, 4.0, 5.0])
                .collect(),
        )),
        von_mises: Some((0..nc).map(|e| e as f64 + 0.5).collect()),
        contact: Some(
            [0, 1, m.n_nodes() - 1]
                .into_iter()
                .map(|node| ContactNode {
                    node,
                    slip_velocity: node as f64,
                    friction_traction: 0.0,
                    bound: 1.0,
                    slipping: true,
                    tangential_velocity: Some([1.0, 0.0, 0.0]),
                    traction: Some([0.0, 1.0, 0.0]),
                })
                .collect(),
        ),
        estimate: Some((0..nc).map(|e| e as f64 + 0.25).collect()),
    }
}

#[test]
fn restricted_fields_are_those_of_the_mapped_nodes_and_owning_cells() {
    let m = Mesh::cuboid(2.0, 0.5, 1.5, 4, 2, 3);
    let s = Surface::of_solid(&m);
    let f = s.restrict(labelled(&m), m.n_nodes(), m.n_cells()).unwrap();
    assert_eq!((f.n, f.t), (3, 0.75));
    let nodes = s.nodes(&m);
    let u = f.u.unwrap();
    let w = f.w.unwrap();
    assert_eq!(u.len(), 3 * nodes.len());
    for (i, p) in nodes.iter().enumerate() {
        assert_eq!(&u[3 * i..3 * i + 3], p);
        assert_eq!(w[3 * i], -p[0]);
    }
    let zeta = f.zeta.unwrap();
    assert!(zeta.iter().zip(&s.node_ids).all(|(&z, &id)| z == id as f64));
    let vm = f.von_mises.unwrap();
    let eta = f.estimate.unwrap();
    let Some(Stress::Solid(sigma)) = f.sigma else {
        panic!("σ of a solid")
    };
    assert_eq!(vm.len(), s.triangles.len());
    assert_eq!(eta.len(), s.triangles.len());
    for (t, &e) in s.cells.iter().enumerate() {
        assert_eq!(vm[t], e as f64 + 0.5);
        assert_eq!(eta[t], e as f64 + 0.25);
        assert_eq!(sigma[t][0], e as f64);
    }
    // Nodes 0, 1 and the last are corners or edges of the box: on the surface, renumbered.
    let contact = f.contact.unwrap();
    assert_eq!(contact.len(), 3);
    for c in &contact {
        assert_eq!(s.node_ids[c.node] as f64, c.slip_velocity);
    }
}

#[test]
fn a_field_of_the_wrong_length_is_named() {
    let m = Mesh::cuboid(1.0, 1.0, 1.0, 2, 2, 2);
    let s = Surface::of_solid(&m);
    let mut f = labelled(&m);
    f.von_mises.as_mut().unwrap().pop();
    let e = s.restrict(f, m.n_nodes(), m.n_cells()).unwrap_err();
    assert_eq!(
        e,
        FieldMismatch {
            field: "von_mises",
            expected: m.n_cells(),
            found: m.n_cells() - 1
        }
    );
    let e = s
        .restrict(labelled(&m), m.n_nodes() + 1, m.n_cells())
        .unwrap_err();
    assert_eq!(e.field, "u");
}

/// The boundary facets only narrow the search: without them (every node a candidate) the
/// surface is the same.
#[test]
fn the_facet_filter_does_not_change_the_surface() {
    let mut m = Mesh::cuboid(2.0, 0.5, 1.5, 4, 2, 3);
    let filtered = Surface::of_solid(&m);
    m.facets.clear();
    assert_eq!(Surface::of_solid(&m), filtered);
}
