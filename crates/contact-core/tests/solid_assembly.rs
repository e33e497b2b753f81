//! Solids (D = 3): the Kuhn box, Bey refinement, prolongation between nested tetrahedral
//! meshes, the 3D viscous stiffness, mass and Laplacian, and the two committed 3D test meshes
//! (preset-meshes/standing-cylinder.msh, tests/meshes/box-rotated.msh). Expected values are
//! computed independently of the code under test (lattice indices, cross products, volumes
//! of the cells), never read back from it.

#![allow(clippy::needless_range_loop)] // Index loops over nodes and components spell out the formulas.

mod common;
use common::dirichlet::BOX_ROTATION;
use contact_core::fem::prolongation::{parent_cells, prolongate};
use contact_core::fem::{assembly, DofMap, Geometry};
use contact_core::linalg::Csr;
use contact_core::mesh::{import, signed_measure, Mesh};
use std::f64::consts::PI;

type V3 = [f64; 3];

fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn norm(a: V3) -> f64 {
    dot(a, a).sqrt()
}

fn mat_vec(m: &[V3; 3], x: V3) -> V3 {
    [dot(m[0], x), dot(m[1], x), dot(m[2], x)]
}

/// A deterministic stream of "random" numbers in [-1, 1).
struct Noise(u64);

impl Noise {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }

    fn vec(&mut self, n: usize) -> Vec<f64> {
        (0..n).map(|_| self.next()).collect()
    }

    fn matrix(&mut self) -> [V3; 3] {
        std::array::from_fn(|_| std::array::from_fn(|_| self.next()))
    }
}

/// The vertices of cell e.
fn corners(m: &Mesh<3>, e: usize) -> [V3; 4] {
    std::array::from_fn(|a| m.nodes[m.cell(e)[a]])
}

/// Signed volumes of the cells.
fn volumes(m: &Mesh<3>) -> Vec<f64> {
    (0..m.n_cells())
        .map(|e| signed_measure(&corners(m, e)))
        .collect()
}

fn centroid(points: &[V3]) -> V3 {
    let n = points.len() as f64;
    std::array::from_fn(|c| points.iter().map(|p| p[c]).sum::<f64>() / n)
}

/// The value at p of the scalar P1 field v on `m`, by a search for a cell whose barycentric
/// coordinates of p are all ≥ −1e-12.
fn evaluate(m: &Mesh<3>, v: &[f64], p: V3) -> f64 {
    for e in 0..m.n_cells() {
        let x = corners(m, e);
        let vol = signed_measure(&x);
        let lam: [f64; 4] = std::array::from_fn(|a| {
            let mut y = x;
            y[a] = p;
            signed_measure(&y) / vol
        });
        if lam.iter().all(|&l| l >= -1e-12) {
            return (0..4).map(|a| lam[a] * v[m.cell(e)[a]]).sum();
        }
    }
    panic!("{p:?} lies in no cell");
}

/// The largest |entry| of a matrix.
fn scale(k: &Csr) -> f64 {
    k.values.iter().fold(0.0, |s, x| s.max(x.abs()))
}

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |s, x| s.max(x.abs()))
}

fn multiply(k: &Csr, v: &[f64]) -> Vec<f64> {
    let mut r = vec![0.0; k.nrows];
    k.mul_vec(v, &mut r);
    r
}

/// The lattice index (i, j, k) of node n of a box with nx × ny × nz cells.
fn lattice_index(n: usize, nx: usize, ny: usize) -> [usize; 3] {
    [
        n % (nx + 1),
        (n / (nx + 1)) % (ny + 1),
        n / ((nx + 1) * (ny + 1)),
    ]
}

/// A boundary triangle found without the mesh's facets: its nodes, outward unit normal and
/// area.
struct Face {
    nodes: [usize; 3],
    normal: V3,
    area: f64,
}

/// The boundary triangles of a Kuhn box from its cells alone: the cell faces whose three
/// vertices lie on one face of the box (lattice index 0 or n along one axis); the normal is
/// that face's ±e_axis, the area from a cross product.
fn box_faces(m: &Mesh<3>, n: [usize; 3]) -> Vec<Face> {
    let mut out = Vec::new();
    for cell in m.cells() {
        for skip in 0..4 {
            let tri: Vec<usize> = (0..4).filter(|&a| a != skip).map(|a| cell[a]).collect();
            let idx: Vec<[usize; 3]> = tri.iter().map(|&v| lattice_index(v, n[0], n[1])).collect();
            for axis in 0..3 {
                for (end, sign) in [(0, -1.0), (n[axis], 1.0)] {
                    if idx.iter().all(|i| i[axis] == end) {
                        let p: Vec<V3> = tri.iter().map(|&v| m.nodes[v]).collect();
                        let mut normal = [0.0; 3];
                        normal[axis] = sign;
                        out.push(Face {
                            nodes: [tri[0], tri[1], tri[2]],
                            normal,
                            area: 0.5 * norm(cross(sub(p[1], p[0]), sub(p[2], p[0]))),
                        });
                    }
                }
            }
        }
    }
    out
}

/// The boundary triangles of a convex body from its facet node lists, with the normal and
/// area computed here: the normal is oriented away from the body's centroid (convexity).
fn convex_faces(m: &Mesh<3>) -> Vec<Face> {
    let c = centroid(&m.nodes);
    m.facets
        .iter()
        .map(|f| {
            let p = f.nodes.map(|v| m.nodes[v]);
            let n = cross(sub(p[1], p[0]), sub(p[2], p[0]));
            let len = norm(n);
            let mut normal = n.map(|x| x / len);
            if dot(normal, sub(centroid(&p), c)) < 0.0 {
                normal = normal.map(|x| -x);
            }
            Face {
                nodes: f.nodes,
                normal,
                area: 0.5 * len,
            }
        })
        .collect()
}

const BOXES: [([f64; 3], [usize; 3]); 3] = [
    ([2.0, 1.0, 1.0], [4, 2, 2]),
    ([1.0, 2.0, 3.0], [3, 4, 5]),
    ([0.7, 1.3, 0.4], [3, 3, 2]),
];

fn cuboid(l: [f64; 3], n: [usize; 3]) -> Mesh<3> {
    Mesh::<3>::cuboid(l[0], l[1], l[2], n[0], n[1], n[2])
}

fn read(name: &str) -> Mesh<3> {
    let dir = if name == "standing-cylinder.msh" {
        "preset-meshes"
    } else {
        "tests/meshes"
    };
    let path = format!("{}/{dir}/{name}", env!("CARGO_MANIFEST_DIR"));
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    import::import::<3>(&bytes).unwrap_or_else(|e| panic!("{name}: {e}"))
}

const R: [V3; 3] = BOX_ROTATION;
const T: V3 = [0.3, -0.2, 0.5];

#[test]
fn kuhn_box_nodes_cells_and_volumes() {
    for (l, n) in BOXES {
        let m = cuboid(l, n);
        let [nx, ny, nz] = n;
        assert_eq!(m.n_nodes(), (nx + 1) * (ny + 1) * (nz + 1));
        assert_eq!(m.n_cells(), 6 * nx * ny * nz);
        for (v, p) in m.nodes.iter().enumerate() {
            let idx = lattice_index(v, nx, ny);
            for a in 0..3 {
                assert_eq!(p[a], idx[a] as f64 * l[a] / n[a] as f64, "node {v}");
            }
        }
        let vol = volumes(&m);
        let cell = l[0] * l[1] * l[2] / (6 * nx * ny * nz) as f64;
        for (e, v) in vol.iter().enumerate() {
            assert!(*v > 0.0, "cell {e} has volume {v}");
            assert!((v / cell - 1.0).abs() < 1e-12, "cell {e}: {v} ≠ {cell}");
        }
        let total: f64 = vol.iter().sum();
        assert!(
            (total - l[0] * l[1] * l[2]).abs() < 1e-13 * total,
            "{total}"
        );
        // Each cube's 6 tetrahedra share its diagonal v000 → v111 and their vertices are a
        // monotone lattice path (one unit step per axis between consecutive path vertices).
        for (e, c) in m.cells().enumerate() {
            let idx: Vec<[usize; 3]> = c.iter().map(|&v| lattice_index(v, nx, ny)).collect();
            let mut path = [idx[0], idx[1], idx[2], idx[3]];
            if path[1].iter().sum::<usize>() > path[2].iter().sum::<usize>() {
                path.swap(1, 2);
            }
            for s in 0..3 {
                let d: Vec<usize> = (0..3).map(|a| path[s + 1][a] - path[s][a]).collect();
                assert_eq!(d.iter().sum::<usize>(), 1, "cell {e}");
            }
            let cube = e / 6;
            let v000 = [cube % nx, (cube / nx) % ny, cube / (nx * ny)];
            assert_eq!(path[0], v000, "cell {e}");
        }
        // The 6 tetrahedra of a cube are distinct.
        for cube in m.cells().collect::<Vec<_>>().chunks(6) {
            let mut sets: Vec<Vec<usize>> = cube
                .iter()
                .map(|c| {
                    let mut s = c.to_vec();
                    s.sort();
                    s
                })
                .collect();
            sets.sort();
            sets.dedup();
            assert_eq!(sets.len(), 6);
        }
    }
}

#[test]
fn kuhn_box_boundary_is_its_surface_with_outward_normals() {
    for (l, n) in BOXES {
        let m = cuboid(l, n);
        let [nx, ny, nz] = n;
        assert_eq!(m.facets.len(), 4 * (nx * ny + ny * nz + nz * nx));
        let area: f64 = m.facets.iter().map(|f| f.measure).sum();
        let surface = 2.0 * (l[0] * l[1] + l[1] * l[2] + l[2] * l[0]);
        assert!(
            (area - surface).abs() < 1e-13 * surface,
            "{area} ≠ {surface}"
        );
        let body = [0.5 * l[0], 0.5 * l[1], 0.5 * l[2]];
        for (i, f) in m.facets.iter().enumerate() {
            let p = f.nodes.map(|v| m.nodes[v]);
            let c = centroid(&p);
            // Outward: away from the centre of the (convex) box, and just outside it.
            assert!(dot(f.normal, sub(c, body)) > 0.0, "facet {i}");
            let out: V3 = std::array::from_fn(|a| c[a] + 1e-6 * f.normal[a]);
            let inside: V3 = std::array::from_fn(|a| c[a] - 1e-6 * f.normal[a]);
            assert!((0..3).any(|a| out[a] < 0.0 || out[a] > l[a]), "facet {i}");
            assert!(
                (0..3).all(|a| inside[a] > 0.0 && inside[a] < l[a]),
                "facet {i}"
            );
            // The vertex order follows the normal, and the measure is the triangle's area.
            let x = cross(sub(p[1], p[0]), sub(p[2], p[0]));
            assert!((0.5 * norm(x) - f.measure).abs() < 1e-15 * surface);
            assert!((0..3).all(|a| (x[a] / norm(x) - f.normal[a]).abs() < 1e-14));
        }
        // The same triangles as found from the cells alone.
        let mut mine: Vec<[usize; 3]> = box_faces(&m, n)
            .iter()
            .map(|f| {
                let mut k = f.nodes;
                k.sort();
                k
            })
            .collect();
        let mut theirs: Vec<[usize; 3]> = m
            .facets
            .iter()
            .map(|f| {
                let mut k = f.nodes;
                k.sort();
                k
            })
            .collect();
        mine.sort();
        theirs.sort();
        assert_eq!(mine, theirs);
        assert!(m.facets.iter().all(|f| f.part.is_none()));
    }
}

#[test]
fn kuhn_boxes_of_h_and_h_over_2_are_nested() {
    let (l, nc) = ([2.0, 1.0, 1.5], [4, 2, 3]);
    let coarse = cuboid(l, nc);
    let fine = cuboid(l, nc.map(|c| 2 * c));
    // Coarse nodes are fine nodes, bit for bit.
    for (v, p) in coarse.nodes.iter().enumerate() {
        let [i, j, k] = lattice_index(v, nc[0], nc[1]);
        let w = 2 * i + (2 * nc[0] + 1) * (2 * j + (2 * nc[1] + 1) * 2 * k);
        assert_eq!(fine.nodes[w], *p);
    }
    // A linear field is reproduced exactly.
    let g = [[1.5, -2.0, 0.25], [0.5, 1.0, -1.0], [-0.3, 0.2, 0.7]];
    let lin = |p: V3| -> V3 { std::array::from_fn(|c| dot(g[c], p) + c as f64) };
    let cv: Vec<f64> = coarse.nodes.iter().flat_map(|&p| lin(p)).collect();
    let fv = prolongate(&coarse, &cv, 3, &fine).unwrap();
    assert_eq!(fv.len(), 3 * fine.n_nodes());
    for (v, &p) in fine.nodes.iter().enumerate() {
        let e = lin(p);
        assert!(
            (0..3).all(|c| (fv[3 * v + c] - e[c]).abs() < 1e-13),
            "node {v}"
        );
    }
    // A random coarse P1 field: its values at the fine nodes.
    let cz = Noise(11).vec(coarse.n_nodes());
    let fz = prolongate(&coarse, &cz, 1, &fine).unwrap();
    for (v, &p) in fine.nodes.iter().enumerate() {
        assert!(
            (fz[v] - evaluate(&coarse, &cz, p)).abs() < 1e-13,
            "node {v}"
        );
    }
    // Every fine tetrahedron lies in its parent, so the field's gradient is the parent's.
    let parents = parent_cells(&coarse, &fine).unwrap();
    let (gc, gf) = (Geometry::new(&coarse), Geometry::new(&fine));
    for (t, &p) in parents.iter().enumerate() {
        let c = centroid(&corners(&fine, t));
        let x = corners(&coarse, p as usize);
        let vol = signed_measure(&x);
        for a in 0..4 {
            let mut y = x;
            y[a] = c;
            assert!(signed_measure(&y) / vol > 0.0, "{t} not in {p}");
        }
        let (ga, gb) = (gf.grads(t), gc.grads(p as usize));
        for c in 0..3 {
            let dfine: f64 = (0..4).map(|a| fz[fine.cell(t)[a]] * ga[a][c]).sum();
            let dcoarse: f64 = (0..4)
                .map(|a| cz[coarse.cell(p as usize)[a]] * gb[a][c])
                .sum();
            assert!((dfine - dcoarse).abs() < 1e-11, "{t}: {dfine} ≠ {dcoarse}");
        }
    }
}

/// The three meshes the operator tests run on: a Kuhn box, the imported cylinder, the
/// imported rotated box.
fn solids() -> Vec<(&'static str, Mesh<3>)> {
    vec![
        ("box", cuboid([2.0, 1.0, 1.0], [4, 2, 2])),
        ("cylinder", read("standing-cylinder.msh")),
        ("rotated box", read("box-rotated.msh")),
    ]
}

#[test]
fn rigid_body_modes_are_the_kernel_of_the_3d_viscous_stiffness() {
    for (name, m) in solids() {
        let geo = Geometry::new(&m);
        let dofs = DofMap::all_free(&m);
        let k = assembly::viscous_stiffness(&m, &geo, &dofs, 2.0, 3.0);
        assert_eq!(k.nrows, 3 * m.n_nodes());
        let (s, d) = (scale(&k), m.diameter());
        let modes: [fn(V3) -> V3; 6] = [
            |_| [1.0, 0.0, 0.0],
            |_| [0.0, 1.0, 0.0],
            |_| [0.0, 0.0, 1.0],
            |p| cross([1.0, 0.0, 0.0], p),
            |p| cross([0.0, 1.0, 0.0], p),
            |p| cross([0.0, 0.0, 1.0], p),
        ];
        for (i, mode) in modes.iter().enumerate() {
            let v: Vec<f64> = m.nodes.iter().flat_map(|&p| mode(p)).collect();
            let r = multiply(&k, &v);
            let size = max_abs(&v).max(d);
            assert!(
                max_abs(&r) < 1e-12 * s * size,
                "{name}: mode {i}: residual {} (scale {s})",
                max_abs(&r)
            );
        }
        // Not everything is in the kernel: a stretch costs energy.
        let stretch: Vec<f64> = m.nodes.iter().flat_map(|p| [p[0], 0.0, 0.0]).collect();
        let r = multiply(&k, &stretch);
        assert!(stretch.iter().zip(&r).map(|(a, b)| a * b).sum::<f64>() > 1e-3);
    }
}

#[test]
fn the_3d_viscous_stiffness_is_symmetric() {
    for (name, m) in solids() {
        let geo = Geometry::new(&m);
        let k = assembly::viscous_stiffness(&m, &geo, &DofMap::all_free(&m), 2.0, 3.0);
        let s = scale(&k);
        for r in 0..k.nrows {
            for idx in k.indptr[r]..k.indptr[r + 1] {
                let c = k.indices[idx] as usize;
                let d = (k.values[idx] - k.get(c, r)).abs();
                assert!(d <= 1e-14 * s, "{name}: K[{r},{c}] − K[{c},{r}] = {d}");
            }
            assert!(k.get(r, r) > 0.0, "{name}: K[{r},{r}] ≤ 0");
        }
    }
}

/// The patch test: for u = G x + c, K u = ∫_∂Ω (A ε) ν ψ_i, i.e. zero at interior nodes and
/// Σ_F |F|/3 (A ε) ν_F over the boundary triangles F at a boundary node.
fn patch_test(name: &str, m: &Mesh<3>, faces: &[Face], seed: u64) {
    let (eta, xi) = (2.0, 3.0);
    let mut noise = Noise(seed);
    let g = noise.matrix();
    let c = [noise.next(), noise.next(), noise.next()];
    let u: Vec<f64> = m
        .nodes
        .iter()
        .flat_map(|&p| {
            let gp = mat_vec(&g, p);
            [gp[0] + c[0], gp[1] + c[1], gp[2] + c[2]]
        })
        .collect();
    let geo = Geometry::new(m);
    let k = assembly::viscous_stiffness(m, &geo, &DofMap::all_free(m), eta, xi);
    let r = multiply(&k, &u);
    // σ = A ε = 2η ε + ξ tr(ε) I with ε = (G + Gᵀ)/2.
    let eps: [V3; 3] = std::array::from_fn(|a| std::array::from_fn(|b| 0.5 * (g[a][b] + g[b][a])));
    let tr = eps[0][0] + eps[1][1] + eps[2][2];
    let sigma: [V3; 3] = std::array::from_fn(|a| {
        std::array::from_fn(|b| 2.0 * eta * eps[a][b] + if a == b { xi * tr } else { 0.0 })
    });
    let mut expected = vec![0.0; u.len()];
    let mut boundary = vec![false; m.n_nodes()];
    for f in faces {
        let t = mat_vec(&sigma, f.normal);
        for &v in &f.nodes {
            boundary[v] = true;
            for a in 0..3 {
                expected[3 * v + a] += f.area / 3.0 * t[a];
            }
        }
    }
    let tol = 1e-12 * scale(&k) * m.diameter();
    let interior = boundary.iter().filter(|b| !**b).count();
    assert!(interior > 0, "{name}: no interior node");
    for v in 0..m.n_nodes() {
        for a in 0..3 {
            let d = r[3 * v + a] - expected[3 * v + a];
            assert!(
                d.abs() < tol,
                "{name}: node {v} ({}) component {a}: K u = {}, expected {}",
                if boundary[v] { "boundary" } else { "interior" },
                r[3 * v + a],
                expected[3 * v + a]
            );
        }
    }
    // The energy is |Ω| σ:ε.
    let energy: f64 = u.iter().zip(&r).map(|(a, b)| a * b).sum();
    let volume: f64 = geo.measures().sum();
    let sig_eps: f64 = (0..3)
        .flat_map(|a| (0..3).map(move |b| (a, b)))
        .map(|(a, b)| sigma[a][b] * eps[a][b])
        .sum();
    assert!(
        (energy - volume * sig_eps).abs() < 1e-11 * volume * sig_eps.abs(),
        "{name}: {energy} ≠ {}",
        volume * sig_eps
    );
}

#[test]
fn patch_test_of_the_3d_viscous_stiffness() {
    for (i, (l, n)) in BOXES.into_iter().enumerate() {
        let m = cuboid(l, n);
        patch_test(&format!("box {l:?}"), &m, &box_faces(&m, n), 17 + i as u64);
    }
    let m = read("standing-cylinder.msh");
    patch_test("cylinder", &m, &convex_faces(&m), 5);
    let m = read("box-rotated.msh");
    patch_test("rotated box", &m, &convex_faces(&m), 6);
}

#[test]
fn the_viscous_energy_does_not_see_the_rotation_of_the_box() {
    let (b, r) = (cuboid([2.0, 1.0, 1.0], [8, 4, 4]), read("box-rotated.msh"));
    let kb = assembly::viscous_stiffness(&b, &Geometry::new(&b), &DofMap::all_free(&b), 2.0, 3.0);
    let kr = assembly::viscous_stiffness(&r, &Geometry::new(&r), &DofMap::all_free(&r), 2.0, 3.0);
    let v = Noise(9).vec(3 * b.n_nodes());
    // The same displacement field, rotated with the body.
    let w: Vec<f64> = v
        .chunks_exact(3)
        .flat_map(|x| mat_vec(&R, [x[0], x[1], x[2]]))
        .collect();
    let energy = |k: &Csr, x: &[f64]| {
        multiply(k, x)
            .iter()
            .zip(x)
            .map(|(a, b)| a * b)
            .sum::<f64>()
    };
    let (eb, er) = (energy(&kb, &v), energy(&kr, &w));
    assert!((eb - er).abs() < 1e-12 * eb, "{eb} ≠ {er}");
}

#[test]
fn the_3d_mass_integrates_the_basis_functions() {
    for (name, m) in solids() {
        let geo = Geometry::new(&m);
        let mass = assembly::mass(&m, &geo);
        let vol: Vec<f64> = volumes(&m).iter().map(|v| v.abs()).collect();
        let total: f64 = vol.iter().sum();
        let sum: f64 = mass.values.iter().sum();
        assert!(
            (sum - total).abs() < 1e-13 * total,
            "{name}: {sum} ≠ {total}"
        );
        // Row sums: ∫ψ_i = Σ_{T ∋ i} |T|/4.
        let mut integral = vec![0.0; m.n_nodes()];
        for (e, c) in m.cells().enumerate() {
            c.iter().for_each(|&v| integral[v] += vol[e] / 4.0);
        }
        let rows = multiply(&mass, &vec![1.0; m.n_nodes()]);
        for v in 0..m.n_nodes() {
            assert!(
                (rows[v] - integral[v]).abs() < 1e-14 * total,
                "{name}: node {v}"
            );
        }
        // The element matrices: ∫ψ_a² = |T|/10 and ∫ψ_a ψ_b = |T|/20 (a ≠ b).
        let mut diagonal = vec![0.0; m.n_nodes()];
        for (e, c) in m.cells().enumerate() {
            c.iter().for_each(|&v| diagonal[v] += vol[e] / 10.0);
        }
        for v in 0..m.n_nodes() {
            assert!(
                (mass.get(v, v) - diagonal[v]).abs() < 1e-15 * total,
                "{name}: {v}"
            );
        }
        let c = m.cell(0);
        let shared: f64 = (0..m.n_cells())
            .filter(|&e| m.cell(e).contains(&c[0]) && m.cell(e).contains(&c[1]))
            .map(|e| vol[e] / 20.0)
            .sum();
        assert!(
            (mass.get(c[0], c[1]) - shared).abs() < 1e-15 * total,
            "{name}"
        );
        // ∫ x² = xᵀ M x is exact for P1 x.
        let (lo, hi) = m.bounding_box();
        if name == "box" {
            let x: Vec<f64> = m.nodes.iter().map(|p| p[0]).collect();
            let xmx: f64 = multiply(&mass, &x).iter().zip(&x).map(|(a, b)| a * b).sum();
            let exact = (hi[0].powi(3) - lo[0].powi(3)) / 3.0 * (hi[1] - lo[1]) * (hi[2] - lo[2]);
            assert!((xmx - exact).abs() < 1e-13 * exact, "{xmx} ≠ {exact}");
        }
    }
}

#[test]
fn the_3d_laplacian_kills_constants_and_measures_gradients() {
    for (name, m) in solids() {
        let geo = Geometry::new(&m);
        let k = assembly::laplacian(&m, &geo);
        let r = multiply(&k, &vec![1.0; m.n_nodes()]);
        assert!(max_abs(&r) < 1e-13 * scale(&k), "{name}: {}", max_abs(&r));
        // fᵀ K f = |a|² |Ω| for f = a·x.
        let a = [0.3, -1.2, 0.8];
        let f: Vec<f64> = m.nodes.iter().map(|&p| dot(a, p)).collect();
        let e: f64 = multiply(&k, &f).iter().zip(&f).map(|(x, y)| x * y).sum();
        let volume: f64 = geo.measures().sum();
        assert!((e - dot(a, a) * volume).abs() < 1e-12 * e, "{name}: {e}");
    }
}

/// Checks one Bey refinement of `coarse`: 8 children per cell, each of an eighth of its
/// parent's volume and inside it, forming a conforming mesh with the parent's boundary.
fn check_bey(name: &str, coarse: &Mesh<3>) -> Mesh<3> {
    let fine = coarse.refine();
    assert_eq!(fine.n_cells(), 8 * coarse.n_cells(), "{name}");
    let (vc, vf) = (volumes(coarse), volumes(&fine));
    for (p, &v) in vc.iter().enumerate() {
        let kids = &vf[8 * p..8 * p + 8];
        for (k, w) in kids.iter().enumerate() {
            assert!((w.abs() / v.abs() - 0.125).abs() < 1e-12, "{name}: {p}.{k}");
            let c = centroid(&corners(&fine, 8 * p + k));
            let x = corners(coarse, p);
            for a in 0..4 {
                let mut y = x;
                y[a] = c;
                assert!(signed_measure(&y) / v > 0.0, "{name}: child {k} not in {p}");
            }
        }
        let sum: f64 = kids.iter().map(|w| w.abs()).sum();
        // Round-off of volumes from coordinates grows with the shape ratio (slivers).
        assert!(
            (sum - v.abs()).abs() < 1e-12 * v.abs(),
            "{name}: {p}: {sum} ≠ {}",
            v.abs()
        );
    }
    // Conforming: the children, made one orientation, pass the mesh checks and have the
    // parent's boundary, each facet split in four.
    let mut cells: Vec<usize> = Vec::new();
    for (e, c) in fine.cells().enumerate() {
        if vf[e] * vc[0] > 0.0 {
            cells.extend_from_slice(c);
        } else {
            cells.extend_from_slice(&[c[0], c[2], c[1], c[3]]);
        }
    }
    let again = Mesh::<3>::from_cells(fine.nodes.clone(), cells).unwrap();
    assert_eq!(again.facets.len(), 4 * coarse.facets.len(), "{name}");
    assert_eq!(fine.facets.len(), 4 * coarse.facets.len(), "{name}");
    let area = |m: &Mesh<3>| m.facets.iter().map(|f| f.measure).sum::<f64>();
    assert!((area(&again) - area(coarse)).abs() < 1e-13 * area(coarse));
    fine
}

#[test]
fn bey_refinement_makes_eight_equal_children() {
    let tet = Mesh::<3>::from_cells(
        vec![
            [0.1, 0.0, 0.2],
            [1.0, 0.1, 0.0],
            [0.2, 0.9, 0.1],
            [0.3, 0.2, 1.1],
        ],
        vec![0, 1, 2, 3],
    )
    .unwrap();
    check_bey("tetrahedron", &tet);
    check_bey("box", &cuboid([2.0, 1.0, 1.0], [2, 1, 1]));
    check_bey("cylinder", &read("standing-cylinder.msh"));
}

#[test]
fn prolongation_through_bey_refinements_is_exact() {
    let coarse = read("standing-cylinder.msh");
    let once = coarse.refine();
    let twice = once.refine();
    let g = [[1.0, -0.5, 2.0], [0.25, 0.75, -1.5], [-2.0, 0.0, 0.5]];
    let lin = |p: V3| -> V3 { std::array::from_fn(|c| dot(g[c], p) - 0.5 * c as f64) };
    let cv: Vec<f64> = coarse.nodes.iter().flat_map(|&p| lin(p)).collect();
    for fine in [&once, &twice] {
        let fv = prolongate(&coarse, &cv, 3, fine).unwrap();
        assert_eq!(fv.len(), 3 * fine.n_nodes());
        for (v, &p) in fine.nodes.iter().enumerate() {
            let e = lin(p);
            assert!(
                (0..3).all(|c| (fv[3 * v + c] - e[c]).abs() < 1e-12),
                "node {v}"
            );
        }
        let parents = parent_cells(&coarse, fine).unwrap();
        let per = fine.n_cells() / coarse.n_cells();
        assert!(per == 8 || per == 64);
        assert!(parents
            .iter()
            .enumerate()
            .all(|(t, &p)| p as usize == t / per));
    }
    // Level by level is the same as at once.
    let step = prolongate(&coarse, &cv, 3, &once).unwrap();
    assert_eq!(
        prolongate(&once, &step, 3, &twice),
        prolongate(&coarse, &cv, 3, &twice)
    );
    assert!(prolongate(&twice, &vec![0.0; twice.n_nodes()], 1, &once).is_none());
}

#[test]
fn the_standing_cylinder_imports_with_its_groups() {
    let m = read("standing-cylinder.msh");
    assert_eq!(m.n_nodes(), 2448);
    assert!(m.n_cells() > 5 * m.n_nodes() / 2, "{} cells", m.n_cells());
    let names: Vec<&str> = m.groups.iter().map(|g| g.name.as_str()).collect();
    assert_eq!(names, ["base", "top", "side"]);
    // The groups partition the boundary.
    let mut seen = vec![0; m.facets.len()];
    m.groups
        .iter()
        .flat_map(|g| &g.facets)
        .for_each(|&f| seen[f] += 1);
    assert!(seen.iter().all(|&s| s == 1));
    let on = |g: usize, test: &dyn Fn(V3) -> bool| {
        m.groups[g]
            .facets
            .iter()
            .all(|&f| m.facets[f].nodes.iter().all(|&v| test(m.nodes[v])))
    };
    assert!(on(0, &|p| p[2] == 0.0));
    assert!(on(1, &|p| (p[2] - 1.5).abs() < 1e-12));
    assert!(on(2, &|p| (p[0].hypot(p[1]) - 0.5).abs() < 1e-9));
    let measure = |g: usize| -> f64 {
        m.groups[g]
            .facets
            .iter()
            .map(|&f| m.facets[f].measure)
            .sum()
    };
    // Facets on chords: slightly less than the exact discs and mantle.
    let disc = PI * 0.25;
    for (g, exact) in [(0, disc), (1, disc), (2, PI * 1.5)] {
        let a = measure(g);
        assert!(
            a < exact && a > 0.98 * exact,
            "{}: {a} vs {exact}",
            names[g]
        );
    }
    for &f in &m.groups[0].facets {
        assert!((m.facets[f].normal[2] + 1.0).abs() < 1e-12);
    }
    for &f in &m.groups[1].facets {
        assert!((m.facets[f].normal[2] - 1.0).abs() < 1e-12);
    }
    let vol = volumes(&m);
    let sign = vol[0].signum();
    assert!(vol.iter().all(|v| v * sign > 0.0));
    let total: f64 = vol.iter().map(|v| v.abs()).sum();
    let exact = PI * 0.25 * 1.5;
    assert!(total < exact && total > 0.98 * exact, "{total} vs {exact}");
}

#[test]
fn the_rotated_box_is_the_moved_kuhn_box() {
    let b = cuboid([2.0, 1.0, 1.0], [8, 4, 4]);
    let r = read("box-rotated.msh");
    assert_eq!((r.n_nodes(), r.n_cells()), (b.n_nodes(), b.n_cells()));
    assert_eq!((r.n_nodes(), r.n_cells()), (225, 768));
    // Same cells, same vertex order; nodes moved by x ↦ R x + t.
    assert!((0..b.n_cells()).all(|e| r.cell(e) == b.cell(e)));
    for (v, (&p, &q)) in b.nodes.iter().zip(&r.nodes).enumerate() {
        let y = mat_vec(&R, p);
        assert!(
            (0..3).all(|c| (y[c] + T[c] - q[c]).abs() < 1e-15 * 4.0),
            "node {v}"
        );
    }
    // R is a rotation.
    for a in 0..3 {
        for c in 0..3 {
            let rr = dot(R[a], R[c]);
            assert!((rr - f64::from(u8::from(a == c))).abs() < 1e-15);
        }
    }
    let total: f64 = volumes(&r).iter().sum();
    assert!((total - 2.0).abs() < 1e-13, "{total}");
    assert!(volumes(&r).iter().all(|&v| v > 0.0));
    // The same boundary facets in the same order, with rotated normals.
    assert_eq!(r.facets.len(), b.facets.len());
    for (f, g) in b.facets.iter().zip(&r.facets) {
        assert_eq!(f.nodes, g.nodes);
        let n = mat_vec(&R, f.normal);
        assert!((0..3).all(|c| (n[c] - g.normal[c]).abs() < 1e-14));
        assert!((f.measure - g.measure).abs() < 1e-14);
    }
    // Groups: clamped x = 0, contact z = 0, load z = 1 and x = 2 (before the move).
    let names: Vec<&str> = r.groups.iter().map(|g| g.name.as_str()).collect();
    assert_eq!(names, ["clamped", "contact", "load"]);
    let faces: [&[(usize, usize)]; 3] = [&[(0, 0)], &[(2, 0)], &[(2, 4), (0, 8)]];
    for (g, (count, area)) in [(32, 1.0), (64, 2.0), (96, 3.0)].into_iter().enumerate() {
        let group = &r.groups[g];
        assert_eq!(group.facets.len(), count, "{}", group.name);
        let a: f64 = group.facets.iter().map(|&f| r.facets[f].measure).sum();
        assert!((a - area).abs() < 1e-13, "{}: {a}", group.name);
        for &f in &group.facets {
            let idx = r.facets[f].nodes.map(|v| lattice_index(v, 8, 4));
            assert!(
                faces[g]
                    .iter()
                    .any(|&(axis, end)| idx.iter().all(|i| i[axis] == end)),
                "{}: facet {f}",
                group.name
            );
        }
    }
}
