use super::support::Support;
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
        assert_eq!(m.n_cells(), tri_per_cell * 32);
        let total: f64 = (0..m.n_cells()).map(|t| m.area(t)).sum();
        assert!((total - 2.0).abs() < 1e-13);
        assert!((0..m.n_cells()).all(|t| m.area(t) > 0.0));
        let perimeter: f64 = m.facets.iter().map(|e| e.measure).sum();
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
    m.tag_boundary(&[Support::Segment(seg)]).unwrap();
    let tagged: Vec<_> = m.facets.iter().filter(|e| e.part == Some(0)).collect();
    assert_eq!(tagged.len(), 2);
    assert!(tagged.iter().all(|e| e.normal == [0.0, -1.0]));
}

/// The rectangle's cells handed to the general constructor.
fn unstructured(m: &Mesh) -> Mesh {
    Mesh::from_cells(m.nodes.clone(), m.cells.clone()).unwrap()
}

#[test]
fn general_constructor_finds_the_rectangles_boundary() {
    for pattern in [
        MeshPattern::Diagonal,
        MeshPattern::AntiDiagonal,
        MeshPattern::Cross,
    ] {
        let m = Mesh::rectangle(2.0, 1.0, 6, 3, pattern);
        let g = unstructured(&m);
        let key = |f: &Facet<2>| {
            let mut k = f.nodes;
            k.sort_unstable();
            k
        };
        let mut a: Vec<_> = m
            .facets
            .iter()
            .map(|f| (key(f), f.nodes, f.normal, f.measure))
            .collect();
        let mut b: Vec<_> = g
            .facets
            .iter()
            .map(|f| (key(f), f.nodes, f.normal, f.measure))
            .collect();
        a.sort_by_key(|x| x.0);
        b.sort_by_key(|x| x.0);
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(&b) {
            assert_eq!((x.0, x.1), (y.0, y.1), "same facet, same direction");
            assert!((0..2).all(|c| (x.2[c] - y.2[c]).abs() < 1e-15) && (x.3 - y.3).abs() < 1e-15);
        }
    }
}

#[test]
fn quality_checks_name_the_first_offender() {
    let sq = vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    let cases: Vec<(Vec<[f64; 2]>, Vec<usize>, MeshError)> = vec![
        (sq.clone(), vec![], MeshError::Empty),
        (
            vec![[0.0, 0.0], [f64::NAN, 0.0], [1.0, 1.0]],
            vec![0, 1, 2],
            MeshError::NotFinite { node: 1 },
        ),
        (
            sq.clone(),
            vec![0, 1, 7],
            MeshError::MissingNode {
                cell: 0,
                node: 7,
                nodes: 4,
            },
        ),
        (
            sq.clone(),
            vec![0, 1, 2, 0, 2, 2],
            MeshError::RepeatedNode { cell: 1, node: 2 },
        ),
        (
            vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.9, 0.3]],
            vec![0, 1, 2, 0, 3, 2],
            MeshError::Folded {
                cell: 1,
                other: 0,
                nodes: vec![0, 2],
            },
        ),
        (
            sq.clone(),
            vec![0, 1, 2, 2, 0, 1],
            MeshError::DuplicateCell { cell: 1, first: 0 },
        ),
        (
            sq.clone(),
            vec![0, 1, 2],
            MeshError::Unreferenced { node: 3 },
        ),
    ];
    for (nodes, cells, want) in cases {
        assert_eq!(Mesh::from_cells(nodes, cells).unwrap_err(), want);
    }
    // A sliver: the third vertex 1e-14 off the line through the other two.
    let err =
        Mesh::from_cells(vec![[0.0, 0.0], [1.0, 0.0], [0.5, 1e-14]], vec![0, 1, 2]).unwrap_err();
    assert!(
        matches!(err, MeshError::Degenerate { cell: 0, .. }),
        "{err}"
    );
    // Three triangles on one edge (the first two on opposite sides of it).
    let fan = vec![[0.0, 0.0], [1.0, 0.0], [0.5, 1.0], [0.5, -1.0], [0.5, 3.0]];
    let err = Mesh::from_cells(fan, vec![0, 1, 2, 0, 1, 3, 0, 1, 4]).unwrap_err();
    assert!(
        matches!(err, MeshError::NonManifold { cell: 2, .. }),
        "{err}"
    );
    // Two triangles touching at a corner only.
    let bow = vec![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]];
    let err = Mesh::from_cells(bow, vec![0, 1, 2, 0, 3, 4]).unwrap_err();
    assert_eq!(err, MeshError::Disconnected { cell: 1 });
    // A fold (on the edge of nodes 0 and 2) and a fan of three (on nodes 4 and 5): whichever
    // the cells meet first is reported, not the lower-numbered facet.
    let both = vec![
        [0.0, 0.0],
        [1.0, 0.0],
        [1.0, 1.0],
        [0.9, 0.3],
        [10.0, 0.0],
        [11.0, 0.0],
        [10.5, 1.0],
        [10.5, -1.0],
        [10.5, 3.0],
    ];
    let (fold, fan) = ([0, 1, 2, 0, 3, 2], [4, 5, 6, 4, 5, 7, 4, 5, 8]);
    let err = Mesh::from_cells(both.clone(), [fan.as_slice(), &fold].concat()).unwrap_err();
    assert_eq!(
        err,
        MeshError::NonManifold {
            nodes: vec![4, 5],
            cell: 2
        }
    );
    let err = Mesh::from_cells(both, [fold.as_slice(), &fan].concat()).unwrap_err();
    assert_eq!(
        err,
        MeshError::Folded {
            cell: 1,
            other: 0,
            nodes: vec![0, 2]
        }
    );
}

#[test]
fn red_refinement_is_nested_and_keeps_tags() {
    let mut m = Mesh::rectangle(2.0, 1.0, 3, 2, MeshPattern::Diagonal);
    let bottom = Segment {
        a: [0.0, 0.0],
        b: [2.0, 0.0],
    };
    m.tag_boundary(&[Support::Segment(bottom)]).unwrap();
    let f = m.refine().refine();
    assert_eq!(f.n_cells(), 16 * m.n_cells());
    let area: f64 = (0..f.n_cells()).map(|t| f.area(t)).sum();
    assert!((area - 2.0).abs() < 1e-13);
    assert!(
        (0..f.n_cells()).all(|t| f.area(t) > 0.0),
        "children keep the orientation"
    );
    // Same node set as the structured mesh of h/4 (both are the same lattice).
    let s = Mesh::rectangle(2.0, 1.0, 12, 8, MeshPattern::Diagonal);
    assert_eq!(f.n_nodes(), s.n_nodes());
    let tagged: f64 = f
        .facets
        .iter()
        .filter(|e| e.part == Some(0))
        .map(|e| e.measure)
        .sum();
    assert!((tagged - 2.0).abs() < 1e-14);
    assert_eq!(f.nesting.len(), 2);
    let nest = f.nesting.last().unwrap();
    for (k, &[a, b]) in nest.midpoints.iter().enumerate() {
        let (p, q, r) = (f.nodes[a], f.nodes[b], f.nodes[nest.coarse_nodes + k]);
        assert!((0..2).all(|c| r[c] == 0.5 * (p[c] + q[c])));
    }
    // Children lie in their parent: each child's centroid has barycentrics in [0, 1].
    let c1 = m.refine();
    for t in 0..c1.n_cells() {
        let parent = m.triangle(t / 4).map(|i| m.nodes[i]);
        let cen = c1.triangle(t).iter().fold([0.0; 2], |s, &i| {
            [s[0] + c1.nodes[i][0] / 3.0, s[1] + c1.nodes[i][1] / 3.0]
        });
        let a = signed_measure(&parent);
        for k in 0..3 {
            let mut q = parent;
            q[k] = cen;
            assert!(signed_measure(&q) / a > 0.0);
        }
    }
}

#[test]
fn bey_refinement_of_a_tetrahedron() {
    let nodes = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
    ];
    let m = Mesh::<3>::from_cells(nodes, vec![0, 1, 2, 3]).unwrap();
    assert_eq!(m.facets.len(), 4);
    let area: f64 = m.facets.iter().map(|f| f.measure).sum();
    assert!((area - (1.5 + 3f64.sqrt() / 2.0)).abs() < 1e-14);
    let f = m.refine();
    assert_eq!((f.n_cells(), f.n_nodes(), f.facets.len()), (8, 10, 16));
    let vol: f64 = f
        .cells()
        .map(|c| signed_measure(&c.iter().map(|&i| f.nodes[i]).collect::<Vec<_>>()).abs())
        .sum();
    assert!((vol - 1.0 / 6.0).abs() < 1e-15);
    assert!(f.cells().all(|c| (signed_measure(
        &c.iter().map(|&i| f.nodes[i]).collect::<Vec<_>>()
    )
    .abs()
        - 1.0 / 48.0)
        .abs()
        < 1e-15));
    // The refined cells form a conforming mesh with the same boundary area.
    let g = Mesh::<3>::from_cells(f.nodes.clone(), f.cells.clone());
    // Bey's children need not share one orientation: they are accepted as they are.
    let g = g.unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(g.facets.len(), 16);
}

/// Whether every interior edge of a 2D mesh has its two triangles on opposite sides
/// (checked independently of `quality`: by the signed areas of the two triangles made of the
/// edge, in one order, and each triangle's third vertex).
fn no_fold(m: &Mesh) -> bool {
    let mut third: std::collections::HashMap<[usize; 2], Vec<usize>> = Default::default();
    for t in m.triangles() {
        for a in 0..3 {
            let (p, q) = (t[(a + 1) % 3], t[(a + 2) % 3]);
            third.entry([p.min(q), p.max(q)]).or_default().push(t[a]);
        }
    }
    third.iter().all(|(e, v)| {
        let side = |r: usize| signed_measure(&[m.nodes[e[0]], m.nodes[e[1]], m.nodes[r]]);
        v.len() != 2 || side(v[0]) * side(v[1]) < 0.0
    })
}

mod hostile {
    use super::*;
    use proptest::prelude::*;

    fn coordinate() -> impl Strategy<Value = f64> {
        prop_oneof![
            8 => (0u8..5).prop_map(f64::from),
            1 => Just(f64::NAN),
            1 => Just(f64::INFINITY),
            2 => -1e3f64..1e3,
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]

        /// Any nodes and cells: a mesh or an error, never a panic; an accepted mesh has
        /// nondegenerate cells, no two on the same side of a shared edge, and boundary facets
        /// with unit outward normals.
        #[test]
        fn from_cells_never_panics(
            nodes in prop::collection::vec([coordinate(), coordinate()], 0..12),
            cells in prop::collection::vec(0usize..14, 0..30),
        ) {
            let n = cells.len() / 3 * 3;
            if let Ok(m) = Mesh::from_cells(nodes, cells[..n].to_vec()) {
                prop_assert!((0..m.n_cells()).all(|t| m.area(t) != 0.0));
                prop_assert!(no_fold(&m));
                prop_assert!(!m.facets.is_empty());
                for f in &m.facets {
                    prop_assert!((f.normal[0].hypot(f.normal[1]) - 1.0).abs() < 1e-12);
                    prop_assert!(f.measure > 0.0);
                }
                let r = m.refine();
                prop_assert_eq!(r.n_cells(), 4 * m.n_cells());
            }
        }

        /// Byte edits of a real file: a checked mesh or an error, never a panic.
        #[test]
        fn import_of_edited_files_never_panics(
            edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6),
            cut in any::<prop::sample::Index>(),
        ) {
            let mut bytes = include_bytes!("../../preset-meshes/plate-with-hole.msh").to_vec();
            for (at, b) in edits {
                let i = at.index(bytes.len());
                bytes[i] = b;
            }
            if cut.index(4) == 0 {
                let end = cut.index(bytes.len());
                bytes.truncate(end);
            }
            let _ = import::import::<2>(&bytes);
        }
    }

    #[test]
    fn the_3d_mesh_is_refused_where_2d_is_needed_and_accepted_as_3d() {
        let bytes = include_bytes!("../../tests/meshes/cylinder.msh");
        let e = import::import::<2>(bytes).unwrap_err();
        assert!(e.to_string().contains("3D"), "{e}");
        let m = import::import::<3>(bytes).unwrap();
        let s = import::summary(&m);
        assert_eq!(s.dimension, 3);
        let names: Vec<_> = s.groups.iter().map(|g| g.name.as_str()).collect();
        assert_eq!(names, ["base", "top", "side"]);
        // Base and top discs of radius 0.5 (facets on chords: slightly less than π/4).
        let pi4 = std::f64::consts::FRAC_PI_4;
        assert!(s.groups[0].measure < pi4 && s.groups[0].measure > 0.97 * pi4);
        let vol: f64 = m
            .cells()
            .map(|c| signed_measure(&c.iter().map(|&i| m.nodes[i]).collect::<Vec<_>>()).abs())
            .sum();
        assert!(vol < pi4 && vol > 0.97 * pi4, "{vol}");
    }

    #[test]
    fn the_plate_imports_with_its_groups() {
        let bytes = include_bytes!("../../preset-meshes/plate-with-hole.msh");
        let m = import::import::<2>(bytes).unwrap();
        let s = import::summary(&m);
        let len = |name: &str| s.groups.iter().find(|g| g.name == name).unwrap().measure;
        assert!((len("clamped") - 1.0).abs() < 1e-12 && (len("contact") - 2.0).abs() < 1e-12);
        let circumference = 2.0 * std::f64::consts::PI * 0.2;
        assert!(len("hole") < circumference && len("hole") > 0.99 * circumference);
        // Area: the plate minus the hole's inscribed polygon.
        let area: f64 = (0..m.n_cells()).map(|t| m.area(t).abs()).sum();
        assert!(
            area > 2.0 - 0.04 * std::f64::consts::PI && area < 2.0 - 0.039 * std::f64::consts::PI,
            "{area}"
        );
        assert_eq!(
            m.facets.len(),
            s.groups.iter().map(|g| g.facets).sum::<usize>()
        );
    }
}

/// Cells listed in either orientation (here every other one reversed) give the same mesh;
/// moving an interior node across its neighbours folds it, which is refused whatever the
/// cells' vertex order.
#[test]
fn either_orientation_is_accepted_and_a_fold_refused_in_both() {
    let m = Mesh::rectangle(1.0, 1.0, 3, 3, MeshPattern::Diagonal);
    let mut mixed = m.cells.clone();
    for (e, c) in mixed.chunks_exact_mut(3).enumerate() {
        if e % 2 == 1 {
            c.swap(1, 2);
        }
    }
    let a = Mesh::from_cells(m.nodes.clone(), m.cells.clone()).unwrap();
    let b = Mesh::from_cells(m.nodes.clone(), mixed.clone()).unwrap();
    assert_eq!(a.facets.len(), b.facets.len());
    for (f, g) in a.facets.iter().zip(&b.facets) {
        let (mut p, mut q) = (f.nodes, g.nodes);
        p.sort_unstable();
        q.sort_unstable();
        assert_eq!((p, f.normal, f.measure), (q, g.normal, g.measure));
    }
    assert_eq!(
        import::summary(&b).negatively_oriented_cells,
        m.n_cells() / 2
    );
    // Node 5 = (1/3, 1/3) moved beyond its neighbour (2/3, 2/3).
    let mut nodes = m.nodes.clone();
    nodes[5] = [0.8, 0.8];
    for cells in [m.cells.clone(), mixed] {
        let err = Mesh::from_cells(nodes.clone(), cells).unwrap_err();
        assert!(matches!(err, MeshError::Folded { .. }), "{err}");
    }
}
