//! Any valid mesh file gives the same body and the same results (SCHEME "Orientation" and
//! "General meshes and 3D"): every test mesh, written here as MSH 2.2 (ASCII and binary) and
//! with each cell's vertices in a random order, reads as the same mesh (the same boundary
//! facets, outward normals, measures, groups and figures) and runs to the same fields to
//! round-off; refined, the 2.2 copy in the file's order gives the fields of the original.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use contact_core::mesh::import::{self, summary_any};
use contact_core::mesh::{signed_measure, AnyMesh, Mesh};
use contact_core::msh::{self, MshMesh};
use contact_core::scene::{self, presets, MeshFiles};
use contact_core::solve::stepper::Simulation;
use contact_core::solve::SolverSettings;
use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};
use serde_json::json;

fn core() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Every mesh the tests have that is a valid body: the presets' meshes and the reader's
/// test files (not its refusal cases, not gmsh's own 2.2 copies).
fn test_meshes() -> Vec<PathBuf> {
    let mut out = Vec::new();
    for dir in ["preset-meshes", "tests/meshes"] {
        for e in std::fs::read_dir(core().join(dir)).unwrap() {
            let p = e.unwrap().path();
            let name = p.file_name().unwrap().to_str().unwrap().to_string();
            if name.ends_with(".msh") && !name.contains("msh22") && !name.starts_with("square-") {
                out.push(p);
            }
        }
    }
    out.sort();
    assert!(out.len() >= 6, "{out:?}");
    out
}

/// The mesh written as MSH 2.2, with cell e's vertices listed in the order `order(e)` (a
/// permutation of 0..=dim): group facets first (tags: physical, then an elementary tag),
/// then the cells (in no physical group).
fn write_msh22(m: &MshMesh, binary: bool, order: &dyn Fn(usize) -> Vec<usize>) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend(format!("$MeshFormat\n2.2 {} 8\n", binary as u8).bytes());
    if binary {
        out.extend(1i32.to_le_bytes());
        out.push(b'\n');
    }
    out.extend(b"$EndMeshFormat\n$PhysicalNames\n");
    out.extend(format!("{}\n", m.physical_names.len()).bytes());
    for n in &m.physical_names {
        out.extend(format!("{} {} \"{}\"\n", n.dim, n.tag, n.name).bytes());
    }
    out.extend(format!("$EndPhysicalNames\n$Nodes\n{}\n", m.nodes.len()).bytes());
    for (p, &tag) in m.nodes.iter().zip(&m.node_tags) {
        if binary {
            out.extend((tag as i32).to_le_bytes());
            p.iter().for_each(|c| out.extend(c.to_le_bytes()));
        } else {
            out.extend(format!("{tag} {:?} {:?} {:?}\n", p[0], p[1], p[2]).bytes());
        }
    }
    out.extend(b"$EndNodes\n$Elements\n");
    let (facet_type, cell_type) = if m.dim == 2 { (1, 2) } else { (2, 4) };
    let mut elements: Vec<(i32, i32, Vec<usize>)> = Vec::new();
    for g in &m.groups {
        elements.extend(g.facets().map(|f| (facet_type, g.tag, f.to_vec())));
    }
    for (e, c) in m.cells().enumerate() {
        elements.push((cell_type, 0, order(e).iter().map(|&k| c[k]).collect()));
    }
    out.extend(format!("{}\n", elements.len()).bytes());
    for (number, (t, physical, nodes)) in elements.iter().enumerate() {
        let tags = [*physical, 1];
        let nodes = nodes.iter().map(|&i| m.node_tags[i]);
        if binary {
            // One block per element: the header then the element.
            for v in [*t, 1, 2, number as i32 + 1, tags[0], tags[1]] {
                out.extend(v.to_le_bytes());
            }
            nodes.for_each(|v| out.extend((v as i32).to_le_bytes()));
        } else {
            let list: Vec<String> = nodes.map(|v| v.to_string()).collect();
            out.extend(
                format!(
                    "{} {t} 2 {} {} {}\n",
                    number + 1,
                    tags[0],
                    tags[1],
                    list.join(" ")
                )
                .bytes(),
            );
        }
    }
    if binary {
        out.push(b'\n');
    }
    out.extend(b"$EndElements\n");
    out
}

fn identity(dim: usize) -> impl Fn(usize) -> Vec<usize> {
    move |_| (0..=dim).collect()
}

/// A permutation of 0..n per cell, from a seed (a xorshift generator: reproducible).
fn shuffles(seed: u64, n: usize) -> impl Fn(usize) -> Vec<usize> {
    move |e| {
        let mut x = (seed ^ (e as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)) | 1;
        let mut p: Vec<usize> = (0..n).collect();
        for i in (1..n).rev() {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            p.swap(i, (x % (i as u64 + 1)) as usize);
        }
        p
    }
}

/// The sign (+1 or −1) of a permutation.
fn parity(p: &[usize]) -> i32 {
    let mut s = 1;
    for i in 0..p.len() {
        for j in i + 1..p.len() {
            if p[i] > p[j] {
                s = -s;
            }
        }
    }
    s
}

#[test]
fn msh22_copies_of_every_test_mesh_read_back_exactly() {
    for path in test_meshes() {
        let m = msh::read(&std::fs::read(&path).unwrap()).unwrap();
        for binary in [false, true] {
            let copy = write_msh22(&m, binary, &identity(m.dim));
            let back = msh::read(&copy).unwrap_or_else(|e| panic!("{path:?}: {e}"));
            assert_eq!(back, m, "{path:?}, binary {binary}");
        }
    }
}

/// Boundary facets by sorted vertex set: (measure, outward normal, group names).
type Boundary<'a, const D: usize> = HashMap<Vec<usize>, (f64, [f64; D], Vec<&'a str>)>;

/// The boundary of a mesh as facet vertex sets with (measure, outward normal, group).
fn boundary<const D: usize>(m: &Mesh<D>) -> Boundary<'_, D> {
    let mut out: Boundary<'_, D> = HashMap::new();
    for f in &m.facets {
        let mut k = f.nodes.to_vec();
        k.sort_unstable();
        out.insert(k, (f.measure, f.normal, Vec::new()));
    }
    for g in &m.groups {
        for &i in &g.facets {
            let mut k = m.facets[i].nodes.to_vec();
            k.sort_unstable();
            out.get_mut(&k).unwrap().2.push(&g.name);
        }
    }
    out
}

fn same_body<const D: usize>(a: &Mesh<D>, b: &Mesh<D>, what: &str) {
    assert_eq!(a.nodes, b.nodes, "{what}");
    assert_eq!(a.n_cells(), b.n_cells(), "{what}");
    for (p, q) in a.cells().zip(b.cells()) {
        let (mut p, mut q) = (p.to_vec(), q.to_vec());
        p.sort_unstable();
        q.sort_unstable();
        assert_eq!(p, q, "{what}");
    }
    let (fa, fb) = (boundary(a), boundary(b));
    assert_eq!(fa.len(), fb.len(), "{what}");
    for (k, (m, n, g)) in &fa {
        let (m2, n2, g2) = &fb[k];
        assert!(
            (m - m2).abs() <= 1e-14 * m,
            "{what}: facet {k:?} measure {m} {m2}"
        );
        for c in 0..D {
            assert!(
                (n[c] - n2[c]).abs() <= 1e-14,
                "{what}: facet {k:?} normal {n:?} {n2:?}"
            );
        }
        assert_eq!(g, g2, "{what}: facet {k:?}");
    }
    let names = |m: &Mesh<D>| m.groups.iter().map(|g| g.name.clone()).collect::<Vec<_>>();
    assert_eq!(names(a), names(b), "{what}");
}

/// The number of cells of the permuted copy that are listed in the negative orientation,
/// counted from the original's signs and the permutations' parities.
fn expected_negative(m: &MshMesh, order: &dyn Fn(usize) -> Vec<usize>) -> usize {
    m.cells()
        .enumerate()
        .filter(|(e, c)| {
            let sign = if m.dim == 2 {
                let p: Vec<[f64; 2]> = c.iter().map(|&v| [m.nodes[v][0], m.nodes[v][1]]).collect();
                signed_measure(&p).signum() as i32
            } else {
                let p: Vec<[f64; 3]> = c.iter().map(|&v| m.nodes[v]).collect();
                signed_measure(&p).signum() as i32
            };
            sign * parity(&order(*e)) < 0
        })
        .count()
}

#[test]
fn random_vertex_orders_in_msh22_give_the_same_body() {
    let meshes: Vec<(PathBuf, Vec<u8>)> = test_meshes()
        .into_iter()
        .map(|p| {
            let b = std::fs::read(&p).unwrap();
            (p, b)
        })
        .collect();
    let mut runner = TestRunner::new(Config {
        cases: 12,
        ..Config::default()
    });
    runner
        .run(
            &(0..meshes.len(), any::<u64>(), any::<bool>()),
            |(i, seed, binary)| {
                let (path, bytes) = &meshes[i];
                let m = msh::read(bytes).unwrap();
                let order = shuffles(seed, m.dim + 1);
                let copy = write_msh22(&m, binary, &order);
                let (a, b) = (
                    import::import_any(bytes).unwrap(),
                    import::import_any(&copy).unwrap_or_else(|e| panic!("{path:?}: {e}")),
                );
                let what = format!("{path:?} seed {seed}");
                match (&a, &b) {
                    (AnyMesh::Plane(a), AnyMesh::Plane(b)) => same_body(a, b, &what),
                    (AnyMesh::Solid(a), AnyMesh::Solid(b)) => same_body(a, b, &what),
                    _ => panic!("{what}: dimension"),
                }
                let (sa, sb) = (summary_any(&a), summary_any(&b));
                prop_assert_eq!(sb.negatively_oriented_cells, expected_negative(&m, &order));
                prop_assert_eq!(sa.groups.len(), sb.groups.len());
                for (ga, gb) in sa.groups.iter().zip(&sb.groups) {
                    prop_assert_eq!((&ga.name, ga.facets), (&gb.name, gb.facets));
                    prop_assert!((ga.measure - gb.measure).abs() <= 1e-13 * ga.measure);
                }
                prop_assert_eq!(&sa.bounding_box, &sb.bounding_box);
                let (fa, fb) = (sa.figures, sb.figures);
                for (x, y) in [
                    (fa.min_cell_size, fb.min_cell_size),
                    (fa.max_cell_size, fb.max_cell_size),
                    (fa.min_quality, fb.min_quality),
                    (fa.mean_quality, fb.mean_quality),
                ] {
                    prop_assert!((x - y).abs() <= 1e-13 * x.abs(), "{} {} {}", what, x, y);
                }
                Ok(())
            },
        )
        .unwrap();
}

/// `domain.mesh` names served from memory.
struct Files(HashMap<String, Vec<u8>>);

impl MeshFiles for Files {
    fn load(&self, name: &str) -> Result<AnyMesh, String> {
        let bytes = self.0.get(name).ok_or(format!("no mesh {name}"))?;
        import::import_any(bytes).map_err(|e| e.to_string())
    }
}

/// The final displacement and damage of a preset run on the mesh `bytes`, at k = 1/4 and
/// `refine` red refinements.
fn run(preset: &str, file: &str, bytes: Vec<u8>, refine: usize) -> (Vec<f64>, Vec<f64>) {
    let mut doc = presets::get(preset).unwrap();
    doc["domain"]["mesh"] = json!(file);
    doc["mesh"] = json!({"refine": refine});
    doc["time"]["k"] = json!("1/4");
    let files = Files(HashMap::from([(file.to_string(), bytes)]));
    let problem = scene::validate_with(&doc, &files).unwrap_or_else(|e| panic!("{e}"));
    fn go<const D: usize>(p: contact_core::problem::Problem) -> (Vec<f64>, Vec<f64>) {
        let mut sim = Simulation::<D>::new(p, SolverSettings::default()).unwrap();
        while !sim.finished() {
            sim.step().unwrap();
        }
        (sim.state.u.clone(), sim.state.zeta.clone())
    }
    if problem.dim() == 3 {
        go::<3>(problem)
    } else {
        go::<2>(problem)
    }
}

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

fn max_abs(a: &[f64]) -> f64 {
    a.iter().fold(0.0, |m, x| m.max(x.abs()))
}

/// The plate (2D) and the cylinder under the standing-cylinder scene (3D): a 2.2 copy with
/// random vertex orders runs to the fields of the 4.1 file; refined once, the 2.2 copy in the
/// file's order too.
#[test]
fn msh22_copies_with_random_vertex_orders_run_to_the_same_fields() {
    for (preset, file, dir) in [
        ("plate-with-hole", "plate-with-hole.msh", "preset-meshes"),
        ("standing-cylinder", "cylinder.msh", "tests/meshes"),
    ] {
        let bytes = std::fs::read(core().join(dir).join(file)).unwrap();
        let m = msh::read(&bytes).unwrap();
        let (u, zeta) = run(preset, file, bytes.clone(), 0);
        assert!(max_abs(&u) > 1e-3, "{preset}: the body moves");
        for (seed, binary) in [(1u64, false), (0x5eed, true)] {
            let copy = write_msh22(&m, binary, &shuffles(seed, m.dim + 1));
            let (u2, zeta2) = run(preset, file, copy, 0);
            let (du, dz) = (max_diff(&u, &u2), max_diff(&zeta, &zeta2));
            eprintln!("{preset}, seed {seed}: |Δu| = {du:e}, |Δζ| = {dz:e}");
            assert!(
                du <= 1e-9 * max_abs(&u),
                "{preset} seed {seed}: |Δu| = {du:e}"
            );
            assert!(
                dz <= 1e-9 * max_abs(&zeta).max(1.0),
                "{preset} seed {seed}: |Δζ| = {dz:e}"
            );
        }
        if m.dim == 2 {
            let (u, zeta) = run(preset, file, bytes, 1);
            let copy = write_msh22(&m, true, &identity(m.dim));
            let (u2, zeta2) = run(preset, file, copy, 1);
            let (du, dz) = (max_diff(&u, &u2), max_diff(&zeta, &zeta2));
            eprintln!("{preset} refined: |Δu| = {du:e}, |Δζ| = {dz:e}");
            assert!(
                du <= 1e-9 * max_abs(&u) && dz <= 1e-9,
                "{preset} refined: {du:e} {dz:e}"
            );
        }
    }
}
