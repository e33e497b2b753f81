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
            sq.clone(),
            vec![0, 1, 2, 0, 3, 2],
            MeshError::Inverted { cell: 1 },
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
    // Three triangles on one edge.
    let fan = vec![[0.0, 0.0], [1.0, 0.0], [0.5, 1.0], [0.5, 2.0], [0.5, 3.0]];
    let err = Mesh::from_cells(fan, vec![0, 1, 2, 0, 1, 3, 0, 1, 4]).unwrap_err();
    assert!(
        matches!(err, MeshError::NonManifold { cell: 2, .. }),
        "{err}"
    );
    // Two triangles touching at a corner only.
    let bow = vec![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]];
    let err = Mesh::from_cells(bow, vec![0, 1, 2, 0, 3, 4]).unwrap_err();
    assert_eq!(err, MeshError::Disconnected { cell: 1 });
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
    let g = match g {
        Ok(g) => g,
        Err(MeshError::Inverted { .. }) => return, // Bey's children need not share one orientation.
        Err(e) => panic!("{e}"),
    };
    assert_eq!(g.facets.len(), 16);
}
