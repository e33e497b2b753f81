use std::collections::{BTreeMap, BTreeSet, HashSet};

use super::super::import;
use super::super::quality::figures;
use super::*;
use crate::mesh::MeshPattern;

fn plate() -> Mesh<2> {
    import::import::<2>(include_bytes!(
        "../../../tests/meshes/plate-with-hole-msh22.msh"
    ))
    .unwrap()
}

fn cylinder() -> Mesh<3> {
    import::import::<3>(include_bytes!("../../../tests/meshes/cylinder.msh")).unwrap()
}

fn points<const D: usize>(mesh: &Mesh<D>, cell: usize) -> Vec<[f64; D]> {
    mesh.cell(cell).iter().map(|&v| mesh.nodes[v]).collect()
}

fn measure<const D: usize>(mesh: &Mesh<D>, cell: usize) -> f64 {
    signed_measure(&points(mesh, cell))
}

fn volume<const D: usize>(mesh: &Mesh<D>) -> f64 {
    (0..mesh.n_cells()).map(|c| measure(mesh, c).abs()).sum()
}

fn sorted<const N: usize>(mut k: [usize; N]) -> [usize; N] {
    k.sort_unstable();
    k
}

/// The exact bits of a point, to find a node by its coordinates.
fn bits<const D: usize>(p: [f64; D]) -> [u64; D] {
    p.map(f64::to_bits)
}

/// Conformity, checked from the cells alone: every face in one or two cells, the faces of
/// one cell exactly the boundary facets, no node at the midpoint of an edge of a cell (where
/// bisection puts every node), every cell of positive measure.
fn assert_conforming<const D: usize>(mesh: &Mesh<D>) {
    let mut faces: BTreeMap<Vec<usize>, usize> = BTreeMap::new();
    let mut edges: BTreeSet<[usize; 2]> = BTreeSet::new();
    for (e, cell) in mesh.cells().enumerate() {
        let m = measure(mesh, e).abs();
        let h = (0..=D)
            .flat_map(|a| (a + 1..=D).map(move |b| (a, b)))
            .map(|(a, b)| length2(&mesh.nodes, cell[a], cell[b]).sqrt())
            .fold(0.0, f64::max);
        assert!(m > 1e-12 * h.powi(D as i32), "cell {e} degenerate: {m:e}");
        for skip in 0..=D {
            let mut f: Vec<usize> = (0..=D).filter(|&j| j != skip).map(|j| cell[j]).collect();
            f.sort_unstable();
            *faces.entry(f).or_default() += 1;
        }
        for a in 0..=D {
            for b in a + 1..=D {
                edges.insert(sorted([cell[a], cell[b]]));
            }
        }
    }
    assert!(
        faces.values().all(|&n| n <= 2),
        "a face in more than two cells"
    );
    let single: BTreeSet<Vec<usize>> = faces
        .iter()
        .filter(|&(_, &n)| n == 1)
        .map(|(f, _)| f.clone())
        .collect();
    let boundary: BTreeSet<Vec<usize>> = mesh
        .facets
        .iter()
        .map(|f| sorted(f.nodes).to_vec())
        .collect();
    assert_eq!(boundary.len(), mesh.facets.len(), "a boundary facet twice");
    assert_eq!(
        single, boundary,
        "the boundary facets are not the faces of one cell"
    );
    let nodes: HashSet<[u64; D]> = mesh.nodes.iter().map(|&p| bits(p)).collect();
    assert_eq!(nodes.len(), mesh.n_nodes(), "two nodes at one point");
    for &[a, b] in &edges {
        let (p, q) = (mesh.nodes[a], mesh.nodes[b]);
        let m: [f64; D] = std::array::from_fn(|c| 0.5 * (p[c] + q[c]));
        assert!(!nodes.contains(&bits(m)), "hanging node on edge {a}–{b}");
    }
}

/// The barycentric coordinates of x in the simplex p (ratios of signed measures).
fn barycentric<const D: usize>(p: &[[f64; D]], x: [f64; D]) -> Vec<f64> {
    let whole = signed_measure(p);
    (0..=D)
        .map(|k| {
            let mut q = p.to_vec();
            q[k] = x;
            signed_measure(&q) / whole
        })
        .collect()
}

/// Everything one step promises about the previous mesh `old` (see the module doc).
fn assert_step<const D: usize>(old: &Mesh<D>, step: &Step<D>, marked: &[usize]) {
    let new = &step.mesh;
    assert_conforming(new);
    // Measure kept, cells in their parents, orientation of the parent.
    let (v0, v1) = (volume(old), volume(new));
    assert!((v1 - v0).abs() <= 1e-12 * v0, "{v0} → {v1}");
    assert_eq!(step.parent.len(), new.n_cells());
    assert!(step.parent.windows(2).all(|w| w[0] <= w[1]));
    for (c, &p) in step.parent.iter().enumerate() {
        let parent = points(old, p);
        assert_eq!(
            measure(new, c) > 0.0,
            measure(old, p) > 0.0,
            "cell {c} flipped"
        );
        for &v in new.cell(c) {
            for l in barycentric(&parent, new.nodes[v]) {
                assert!(
                    (-1e-12..=1.0 + 1e-12).contains(&l),
                    "cell {c} not in {p}: {l}"
                );
            }
        }
    }
    let mut children = vec![0; old.n_cells()];
    step.parent.iter().for_each(|&p| children[p] += 1);
    for &c in marked {
        assert!(children[c] >= 2, "marked cell {c} not bisected");
    }
    for (p, &k) in children.iter().enumerate() {
        if k == 1 {
            let c = step.parent.iter().position(|&q| q == p).unwrap();
            assert_eq!(new.cell(c), old.cell(p), "an untouched cell changed");
        }
    }
    // Nodes: the old ones kept, each new one the midpoint of two earlier ones.
    assert_eq!(&new.nodes[..old.n_nodes()], &old.nodes[..]);
    assert_eq!(new.n_nodes(), old.n_nodes() + step.midpoints.len());
    let scale = old.diameter();
    for (k, &(n, [a, b])) in step.midpoints.iter().enumerate() {
        assert_eq!(n, old.n_nodes() + k);
        assert!(a < n && b < n && a != b);
        for c in 0..D {
            let m = 0.5 * (new.nodes[a][c] + new.nodes[b][c]);
            assert!((new.nodes[n][c] - m).abs() <= 1e-14 * scale);
        }
    }
    assert!(new.grid.is_none() && new.lattice.is_none() && new.nesting.is_empty());
    // Facets: in their parents, with the parent's part, normal and groups; measures per
    // parent (hence per part and group) kept.
    assert_eq!(step.facet_parent.len(), new.facets.len());
    let mut pieces = vec![0.0; old.facets.len()];
    for (i, f) in new.facets.iter().enumerate() {
        let p = &old.facets[step.facet_parent[i]];
        assert_eq!((f.part, f.normal), (p.part, p.normal));
        assert!((facet_measure(&new.nodes, &f.nodes) - f.measure).abs() <= 1e-14 * scale);
        pieces[step.facet_parent[i]] += f.measure;
        // Same orientation as the parent, and in its plane (or on its line).
        let (f0, p0) = (new.nodes[f.nodes[0]], new.nodes[p.nodes[0]]);
        let (_, n, _) = super::super::facet_frame(
            &new.nodes,
            f.nodes,
            std::array::from_fn(|c| f0[c] - p.normal[c]),
        );
        let along: f64 = (0..D).map(|c| n[c] * p.normal[c]).sum();
        assert!((along - 1.0).abs() < 1e-12);
        for &v in &f.nodes {
            let off: f64 = (0..D)
                .map(|c| (new.nodes[v][c] - p0[c]) * p.normal[c])
                .sum();
            assert!(off.abs() <= 1e-12 * scale);
        }
        let (nodes_f, _, _) = super::super::facet_frame(
            &new.nodes,
            f.nodes,
            std::array::from_fn(|c| f0[c] - p.normal[c]),
        );
        assert_eq!(nodes_f, f.nodes, "facet {i} not ordered along its normal");
    }
    for (p, f) in old.facets.iter().enumerate() {
        assert!((pieces[p] - f.measure).abs() <= 1e-12 * f.measure);
    }
    assert_eq!(
        old.groups.iter().map(|g| &g.name).collect::<Vec<_>>(),
        new.groups.iter().map(|g| &g.name).collect::<Vec<_>>()
    );
    for (g, h) in old.groups.iter().zip(&new.groups) {
        let members: BTreeSet<usize> = g.facets.iter().copied().collect();
        let expected: Vec<usize> = (0..new.facets.len())
            .filter(|&i| members.contains(&step.facet_parent[i]))
            .collect();
        let mut got = h.facets.clone();
        got.sort_unstable();
        assert_eq!(got, expected, "group {}", g.name);
    }
}

/// The cells around the node nearest to `point` (a grading towards it).
fn around<const D: usize>(mesh: &Mesh<D>, point: [f64; D]) -> Vec<usize> {
    let d = |p: &[f64; D]| (0..D).map(|c| (p[c] - point[c]).powi(2)).sum::<f64>();
    let near = (0..mesh.n_nodes())
        .min_by(|&a, &b| d(&mesh.nodes[a]).total_cmp(&d(&mesh.nodes[b])))
        .unwrap();
    (0..mesh.n_cells())
        .filter(|&c| mesh.cell(c).contains(&near))
        .collect()
}

/// The cells whose centroid lies within `r` of `point`, and those [`around`] it: a ball of
/// refinement that shrinks by `shrink` per call (a graded mesh towards the point).
fn ball<const D: usize>(
    point: [f64; D],
    r: f64,
    shrink: f64,
) -> impl FnMut(&Mesh<D>) -> Vec<usize> {
    let mut r = r / shrink;
    move |mesh| {
        r *= shrink;
        let mut cells = around(mesh, point);
        cells.extend((0..mesh.n_cells()).filter(|&c| {
            let p = points(mesh, c);
            let d2: f64 = (0..D)
                .map(|k| (p.iter().map(|x| x[k]).sum::<f64>() / (D + 1) as f64 - point[k]).powi(2))
                .sum();
            d2 < r * r
        }));
        cells
    }
}

/// A seeded pseudo-random fifth of the cells.
fn fifth(n: usize, seed: &mut u64) -> Vec<usize> {
    share(n, 5, seed)
}

/// A seeded pseudo-random 1/k of the cells (splitmix64).
fn share(n: usize, k: u64, seed: &mut u64) -> Vec<usize> {
    (0..n)
        .filter(|_| {
            *seed = seed.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = *seed;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            (z ^ (z >> 31)).is_multiple_of(k)
        })
        .collect()
}

/// Ten cycles of `mark`, every step checked; the final bisection and the smallest ratio of
/// min quality to the initial mesh's over the cycles.
fn cycles<const D: usize>(
    mesh: &Mesh<D>,
    mut mark: impl FnMut(&Mesh<D>) -> Vec<usize>,
) -> (Bisection<D>, f64) {
    let q0 = figures(mesh).min_quality;
    let mut b = Bisection::new(mesh);
    let mut ratio: f64 = 1.0;
    for _ in 0..10 {
        let old = b.mesh().clone();
        let marked = mark(&old);
        let step = b.refine(&marked);
        assert_step(&old, &step, &marked);
        assert_eq!(b.mesh().cells_flat(), step.mesh.cells_flat());
        ratio = ratio.min(figures(&step.mesh).min_quality / q0);
    }
    (b, ratio)
}

/// Cycles of `mark` (each checked), then [`assert_nodes_of_uniform`].
fn nested_in_uniform<const D: usize>(
    mesh: &Mesh<D>,
    n: usize,
    mut mark: impl FnMut(&Mesh<D>) -> Vec<usize>,
) {
    let mut b = Bisection::new(mesh);
    for _ in 0..n {
        let old = b.mesh().clone();
        let marked = mark(&old);
        let step = b.refine(&marked);
        assert_step(&old, &step, &marked);
    }
    assert_nodes_of_uniform(mesh, &b);
}

/// Every node of `adaptive` is a node of the mesh of `mesh` with all cells bisected as
/// often as the most bisected cell of `adaptive` (the bisection forest is unique).
fn assert_nodes_of_uniform<const D: usize>(mesh: &Mesh<D>, adaptive: &Bisection<D>) {
    let depth = (0..adaptive.mesh().n_cells())
        .map(|c| adaptive.generation(c))
        .max()
        .unwrap();
    let mut uniform = Bisection::new(mesh);
    while (0..uniform.mesh().n_cells()).any(|c| uniform.generation(c) < depth) {
        let coarse: Vec<usize> = (0..uniform.mesh().n_cells())
            .filter(|&c| uniform.generation(c) < depth)
            .collect();
        uniform.refine(&coarse);
    }
    let all: HashSet<[u64; D]> = uniform.mesh().nodes.iter().map(|&p| bits(p)).collect();
    let missing = adaptive
        .mesh()
        .nodes
        .iter()
        .filter(|&&p| !all.contains(&bits(p)))
        .count();
    assert_eq!(
        missing, 0,
        "adaptive nodes not in the uniform mesh of depth {depth}"
    );
    assert!(uniform.mesh().n_nodes() > adaptive.mesh().n_nodes());
}

#[test]
fn an_empty_marking_returns_the_same_mesh() {
    let m = Mesh::rectangle(2.0, 1.0, 4, 2, MeshPattern::Diagonal);
    let mut b = Bisection::new(&m);
    let s = b.refine(&[]);
    assert_eq!(s.mesh.nodes, m.nodes);
    assert_eq!(s.mesh.cells_flat(), m.cells_flat());
    assert_eq!(s.mesh.facets, m.facets);
    assert_eq!(s.mesh.grid, m.grid);
    assert!(s.midpoints.is_empty());
    assert_eq!(s.parent, (0..m.n_cells()).collect::<Vec<_>>());
    let c = cylinder();
    let s = Bisection::new(&c).refine(&[]);
    assert_eq!(
        (
            &s.mesh.nodes,
            s.mesh.cells_flat(),
            &s.mesh.facets,
            &s.mesh.groups
        ),
        (&c.nodes, c.cells_flat(), &c.facets, &c.groups)
    );
}

#[test]
fn one_marked_triangle_bisects_it_and_its_neighbour_across_the_diagonal() {
    // Two triangles of one square share their longest edge, the diagonal: bisecting one
    // bisects the other too (no hanging node), and nothing else.
    let m = Mesh::rectangle(1.0, 1.0, 1, 1, MeshPattern::Diagonal);
    let mut b = Bisection::new(&m);
    let s = b.refine(&[0]);
    assert_step(&m, &s, &[0]);
    assert_eq!((s.mesh.n_cells(), s.mesh.n_nodes()), (4, 5));
    assert_eq!(s.mesh.nodes[4], [0.5, 0.5]);
    assert_eq!(s.midpoints, [(4, [0, 3])]);
    assert_eq!(s.parent, [0, 0, 1, 1]);
    // On a 2 × 2 grid, one corner triangle's bisection spreads to its square's other half only.
    let m = Mesh::rectangle(1.0, 1.0, 2, 2, MeshPattern::Diagonal);
    let s = Bisection::new(&m).refine(&[0]);
    assert_step(&m, &s, &[0]);
    assert_eq!(s.mesh.n_cells(), m.n_cells() + 2);
}

#[test]
fn marking_order_and_repeats_do_not_change_the_result() {
    let m = plate();
    let marked: Vec<usize> = (0..m.n_cells()).step_by(7).collect();
    let mut shuffled: Vec<usize> = marked.iter().rev().copied().collect();
    shuffled.extend_from_slice(&marked[..5]);
    let a = Bisection::new(&m).refine(&marked);
    let b = Bisection::new(&m).refine(&shuffled);
    assert_eq!(a.mesh.nodes, b.mesh.nodes);
    assert_eq!(a.mesh.cells_flat(), b.mesh.cells_flat());
    assert_eq!(a.mesh.facets, b.mesh.facets);
    assert_eq!(a.midpoints, b.midpoints);
}

/// Where the longest edges pair up (each is the longest edge of both its triangles, as in
/// the generated rectangles), bisecting every triangle twice cuts every edge once: the red
/// refinement's nodes, no more. Elsewhere (the imported plate) the closure bisects some
/// triangles a third time, so the red nodes are a subset.
#[test]
fn bisecting_every_triangle_twice_gives_the_red_refinement_s_nodes() {
    for (m, exact) in [
        (Mesh::rectangle(2.0, 1.0, 4, 3, MeshPattern::Diagonal), true),
        (Mesh::rectangle(1.0, 1.0, 3, 3, MeshPattern::Cross), true),
        (plate(), false),
    ] {
        let mut b = Bisection::new(&m);
        for _ in 0..2 {
            let all: Vec<usize> = (0..b.mesh().n_cells()).collect();
            let old = b.mesh().clone();
            let s = b.refine(&all);
            assert_step(&old, &s, &all);
        }
        let red = m.refine();
        let set = |m: &Mesh<2>| m.nodes.iter().map(|&p| bits(p)).collect::<BTreeSet<_>>();
        let (bisected, red_nodes) = (set(b.mesh()), set(&red));
        assert!(red_nodes.is_subset(&bisected));
        assert!((0..b.mesh().n_cells()).all(|c| b.generation(c) >= 2));
        if exact {
            assert_eq!(bisected, red_nodes);
            assert_eq!(b.mesh().n_cells(), red.n_cells());
            assert!((0..b.mesh().n_cells()).all(|c| b.generation(c) == 2));
        } else {
            println!(
                "plate bisected twice everywhere: {} nodes, the red refinement {}",
                bisected.len(),
                red_nodes.len()
            );
        }
    }
}

#[test]
fn rectangle_refined_towards_a_corner_stays_conforming_regular_and_nested() {
    let m = Mesh::rectangle(2.0, 1.0, 4, 2, MeshPattern::Diagonal);
    let (b, ratio) = cycles(&m, |mesh| around(mesh, [0.0, 0.0]));
    let f = figures(b.mesh());
    println!(
        "rectangle, corner: {} nodes, {} cells, min quality {:.3} (ratio {ratio:.3}), h {:.2e}…{:.2e}",
        b.mesh().n_nodes(),
        b.mesh().n_cells(),
        f.min_quality,
        f.min_cell_size,
        f.max_cell_size
    );
    // Right isosceles triangles bisected at their hypotenuse stay similar.
    assert!((ratio - 1.0).abs() < 1e-12, "{ratio}");
    // Graded: the corner's cells are 2^-5 of the initial size (10 bisections).
    assert!(f.min_cell_size < f.max_cell_size / 30.0);
    assert_nodes_of_uniform(&m, &b);
}

#[test]
fn random_fifths_of_the_rectangle_and_the_plate_keep_quality() {
    let mut seed = 38;
    for (name, m) in [
        (
            "rectangle",
            Mesh::rectangle(2.0, 1.0, 4, 3, MeshPattern::AntiDiagonal),
        ),
        ("plate", plate()),
    ] {
        let (b, ratio) = cycles(&m, |mesh| fifth(mesh.n_cells(), &mut seed));
        println!(
            "{name}, random fifths: {} → {} nodes, {} → {} cells, min quality ratio {ratio:.3}",
            m.n_nodes(),
            b.mesh().n_nodes(),
            m.n_cells(),
            b.mesh().n_cells()
        );
        assert!(ratio >= 0.3, "{name}: {ratio}");
        assert!(b.mesh().n_cells() > 4 * m.n_cells());
    }
}

#[test]
fn the_plate_refined_at_its_hole_keeps_its_groups() {
    let m = plate();
    let names: Vec<_> = m.groups.iter().map(|g| g.name.clone()).collect();
    assert!(names.iter().any(|n| n == "hole"), "{names:?}");
    let (b, ratio) = cycles(&m, ball([0.7, 0.25], 0.3, 0.75));
    let length = |mesh: &Mesh<2>, name: &str| -> f64 {
        let g = mesh.groups.iter().find(|g| g.name == name).unwrap();
        g.facets.iter().map(|&f| mesh.facets[f].measure).sum()
    };
    for name in &names {
        let (a, z) = (length(&m, name), length(b.mesh(), name));
        assert!((a - z).abs() <= 1e-12 * a, "{name}: {a} → {z}");
    }
    println!(
        "plate, graded at the hole: {} → {} nodes, {} → {} cells, min quality ratio {ratio:.3}",
        m.n_nodes(),
        b.mesh().n_nodes(),
        m.n_cells(),
        b.mesh().n_cells()
    );
    assert!(ratio >= 0.3, "{ratio}");
    assert!(b.mesh().n_cells() > m.n_cells());
}

#[test]
fn the_cuboid_refined_towards_a_corner_and_at_random_stays_conforming_and_regular() {
    let m = Mesh::cuboid(2.0, 1.0, 1.0, 4, 2, 2);
    let (b, ratio) = cycles(&m, ball([0.0, 0.0, 0.0], 0.6, 0.8));
    println!(
        "cuboid, corner: {} → {} nodes, {} → {} cells, min quality ratio {ratio:.3}",
        m.n_nodes(),
        b.mesh().n_nodes(),
        m.n_cells(),
        b.mesh().n_cells()
    );
    assert!(ratio >= 0.1, "{ratio}");
    let m = Mesh::cuboid(2.0, 1.0, 1.0, 2, 1, 1);
    let mut seed = 7;
    let (b, ratio) = cycles(&m, |mesh| fifth(mesh.n_cells(), &mut seed));
    println!(
        "cuboid, random fifths: {} → {} nodes, {} → {} cells, min quality ratio {ratio:.3}",
        m.n_nodes(),
        b.mesh().n_nodes(),
        m.n_cells(),
        b.mesh().n_cells()
    );
    assert!(ratio >= 0.1, "{ratio}");
    assert!(b.mesh().n_cells() > 4 * m.n_cells());
}

#[test]
fn the_imported_cylinder_refined_at_its_rim_keeps_groups_and_quality() {
    let m = cylinder();
    let (b, ratio) = cycles(&m, ball([0.5, 0.0, 1.0], 0.3, 0.75));
    let area = |mesh: &Mesh<3>, name: &str| -> f64 {
        let g = mesh.groups.iter().find(|g| g.name == name).unwrap();
        g.facets.iter().map(|&f| mesh.facets[f].measure).sum()
    };
    for name in ["base", "top", "side"] {
        let (a, z) = (area(&m, name), area(b.mesh(), name));
        assert!((a - z).abs() <= 1e-12 * a, "{name}: {a} → {z}");
    }
    println!(
        "cylinder, graded at the rim: {} → {} nodes, {} → {} cells, min quality {:.3} → {:.3} (ratio {ratio:.3})",
        m.n_nodes(),
        b.mesh().n_nodes(),
        m.n_cells(),
        b.mesh().n_cells(),
        figures(&m).min_quality,
        figures(b.mesh()).min_quality
    );
    assert!(ratio >= 0.1, "{ratio}");
    assert!(b.mesh().n_cells() > m.n_cells());
}

#[test]
fn the_cylinder_at_random_keeps_quality() {
    let m = cylinder();
    let mut seed = 2000;
    // Ten cycles of a twentieth each (a fifth would make millions of cells).
    let (b, ratio) = cycles(&m, |mesh| share(mesh.n_cells(), 20, &mut seed));
    println!(
        "cylinder, 10 cycles of random twentieths: {} → {} nodes, {} → {} cells, min quality ratio {ratio:.3}",
        m.n_nodes(),
        b.mesh().n_nodes(),
        m.n_cells(),
        b.mesh().n_cells()
    );
    assert!(ratio >= 0.1, "{ratio}");
}

/// The types of AMP's marked tetrahedra after one bisection are all planar, and then cycle
/// Pu → Pf → A → Pu (what bounds the shapes).
#[test]
fn tetrahedra_types_cycle_after_the_first_bisection() {
    fn kind(m: &Marked) -> &'static str {
        let [x0, x1, x2, x3] = m.v;
        let [e0, e1] = m.faces;
        if [x2, x3]
            .into_iter()
            .any(|k| same(e0, [x1, k]) && same(e1, [x0, k]))
        {
            if m.flag {
                "Pf"
            } else {
                "Pu"
            }
        } else if same(e0, [x2, x3]) || same(e1, [x2, x3]) {
            "MO"
        } else {
            "A"
        }
    }
    let m = cylinder();
    let mut b = Bisection::new(&m);
    let mut kinds: Vec<&str> = b.cells.iter().map(kind).collect();
    for _ in 0..4 {
        let all: Vec<usize> = (0..b.mesh().n_cells()).collect();
        let generation: Vec<usize> = (0..b.mesh().n_cells()).map(|c| b.generation(c)).collect();
        let s = b.refine(&all);
        for (c, &p) in s.parent.iter().enumerate() {
            let (was, is) = (kinds[p], kind(&b.cells[c]));
            if b.generation(c) == generation[p] + 1 {
                let expected = match was {
                    "Pu" => "Pf",
                    "Pf" => "A",
                    _ => "Pu",
                };
                assert_eq!(is, expected, "a child of {was}");
            }
        }
        kinds = b.cells.iter().map(kind).collect();
    }
}

#[test]
fn adaptive_nodes_are_nodes_of_the_uniform_bisection_at_the_same_depth() {
    let mut seed = 3;
    let rectangle = Mesh::rectangle(2.0, 1.0, 4, 3, MeshPattern::AntiDiagonal);
    nested_in_uniform(&rectangle, 4, |m| fifth(m.n_cells(), &mut seed));
    nested_in_uniform(&plate(), 3, |m| fifth(m.n_cells(), &mut seed));
    nested_in_uniform(&plate(), 4, |m| around(m, [0.7, 0.25]));
    let cuboid = Mesh::cuboid(2.0, 1.0, 1.0, 2, 1, 1);
    nested_in_uniform(&cuboid, 4, |m| fifth(m.n_cells(), &mut seed));
    nested_in_uniform(&cuboid, 6, |m| around(m, [0.0, 0.0, 0.0]));
    nested_in_uniform(&cylinder(), 2, |m| fifth(m.n_cells(), &mut seed));
}

/// Every tetrahedron bisected (at least) twelve times, four periods of the type cycle: the shapes
/// stay in the classes of the first bisections, so the quality does not decay.
#[test]
fn repeated_bisection_of_every_tetrahedron_keeps_the_shapes() {
    // A box, and a single irregular tetrahedron (no symmetry to help).
    let irregular = Mesh::from_cells(
        vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.1, 0.0],
            [0.3, 0.9, 0.1],
            [0.2, 0.3, 0.8],
        ],
        vec![0, 1, 2, 3],
    )
    .unwrap();
    for (name, m) in [
        ("box", Mesh::cuboid(1.0, 1.0, 1.0, 1, 1, 1)),
        ("tetrahedron", irregular),
    ] {
        let q0 = figures(&m).min_quality;
        let mut b = Bisection::new(&m);
        let mut qualities = Vec::new();
        for _ in 0..12 {
            let all: Vec<usize> = (0..b.mesh().n_cells()).collect();
            b.refine(&all);
            qualities.push(figures(b.mesh()).min_quality / q0);
        }
        println!("{name}, every cell bisected at least 12 times: {} cells, min quality ratio per level {qualities:.3?}", b.mesh().n_cells());
        let last = qualities[qualities.len() - 3..]
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min);
        let earlier = qualities[qualities.len() - 6..qualities.len() - 3]
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min);
        assert!(
            (last - earlier).abs() < 1e-9,
            "{name}: the shapes decay: {qualities:?}"
        );
        assert!(last >= 0.1, "{name}: {last}");
    }
}

/// A polygon mesh (the L-bracket's shape), tagged and graded towards its re-entrant corner:
/// the corners stay nodes, the tagged side keeps its part and length.
#[test]
fn the_polygon_mesh_graded_at_its_reentrant_corner_keeps_corners_parts_and_quality() {
    use crate::mesh::support::Support;
    use crate::mesh::{polygon, Segment};
    let outer = [
        [0.0, 0.0],
        [2.0, 0.0],
        [2.0, 1.0],
        [1.0, 1.0],
        [1.0, 2.0],
        [0.0, 2.0],
    ];
    let t = polygon::triangulate(&outer, &[], 0.25, 100_000).unwrap();
    let mut m = Mesh::from_cells(t.nodes, t.triangles.concat()).unwrap();
    let bottom = Segment {
        a: [0.0, 0.0],
        b: [2.0, 0.0],
    };
    m.tag_boundary(&[Support::Segment(bottom)]).unwrap();
    let tagged = |mesh: &Mesh<2>| -> f64 {
        mesh.facets
            .iter()
            .filter(|f| f.part == Some(0))
            .map(|f| f.measure)
            .sum()
    };
    assert!((tagged(&m) - 2.0).abs() < 1e-12);
    let (b, ratio) = cycles(&m, ball([1.0, 1.0], 0.3, 0.75));
    println!(
        "L-shaped polygon, graded at (1, 1): {} → {} nodes, {} → {} cells, min quality ratio {ratio:.3}",
        m.n_nodes(),
        b.mesh().n_nodes(),
        m.n_cells(),
        b.mesh().n_cells()
    );
    assert!(ratio >= 0.3, "{ratio}");
    assert!((tagged(b.mesh()) - 2.0).abs() < 1e-12);
    for corner in outer {
        assert!(b.mesh().nodes.contains(&corner), "{corner:?}");
    }
    let f = figures(b.mesh());
    assert!(f.min_cell_size < f.max_cell_size / 20.0, "{f:?}");
}
