//! Three dimensions (docs/src/explanation/numerics.md#meshes, #contact-frames): P1 tetrahedra converge at
//! order 1 on a manufactured solution; a box scene and a copy of it rotated about an
//! oblique axis (imported from gmsh, loads rotated) give the same norms with slip in an
//! oblique direction on Γ3; every step of the box scenes keeps the invariants (residuals,
//! 0 ≤ ζ ≤ 1, w · n_i = 0, the isotropic friction law); the VTU of a box has tetrahedra
//! and 6-component stresses.

mod common;
use base64::Engine;
use common::dirichlet::{self, BOX_ROTATION};
use contact_core::expr::Expr;
use contact_core::fem::loads::cell_rule;
use contact_core::fem::{assembly, Geometry};
use contact_core::mesh::{AnyMesh, Mesh};
use contact_core::output::vtk::{write_vtu, Compression};
use contact_core::problem::{Problem, ScalarField, VectorField};
use contact_core::scene::{self, presets, MeshFiles};
use contact_core::solve::invariants;
use contact_core::solve::stepper::{Simulation, StepReport, Stress};
use serde_json::{json, Value};

const ETA: f64 = 1.0;
const XI: f64 = 0.5;

/// ‖ε(w*) − ε(w_h)‖_L2 by the 4-point rule, ε(w*) = (xx, yy, zz, xy, yz, xz) pointwise.
fn strain_error(mesh: &Mesh<3>, w: &[f64], eps: impl Fn([f64; 3]) -> [f64; 6]) -> f64 {
    let geo = Geometry::new(mesh);
    let mut sum = 0.0;
    for (e, cell) in mesh.cells().enumerate() {
        let h = geo.strain(mesh, e, w);
        for (l, wq) in cell_rule(3) {
            let p: [f64; 3] =
                std::array::from_fn(|c| (0..4).map(|a| l[a] * mesh.nodes[cell[a]][c]).sum());
            let x = eps(p);
            let d = [
                x[0] - h[(0, 0)],
                x[1] - h[(1, 1)],
                x[2] - h[(2, 2)],
                x[3] - h[(0, 1)],
                x[4] - h[(1, 2)],
                x[5] - h[(0, 2)],
            ];
            let sq = d[0] * d[0]
                + d[1] * d[1]
                + d[2] * d[2]
                + 2.0 * (d[3] * d[3] + d[4] * d[4] + d[5] * d[5]);
            sum += wq * geo.measure(e) * sq;
        }
    }
    sum.sqrt()
}

fn formula(s: &str) -> ScalarField {
    ScalarField::Expr(Expr::parse(s).unwrap())
}

#[test]
fn a_linear_velocity_is_reproduced_exactly_on_tetrahedra() {
    let mesh = Mesh::cuboid(1.0, 1.0, 1.0, 3, 3, 3);
    let g = [[0.1, 0.3, -0.2], [-0.2, 0.05, 0.4], [0.3, -0.1, 0.2]];
    let exact = |p: [f64; 3]| -> [f64; 3] {
        std::array::from_fn(|r| 0.1 * r as f64 + (0..3).map(|c| g[r][c] * p[c]).sum::<f64>())
    };
    let w = dirichlet::solve(&mesh, (ETA, XI), &VectorField::constant3([0.0; 3]), exact);
    for (i, p) in mesh.nodes.iter().enumerate() {
        let v = exact(*p);
        for c in 0..3 {
            assert!((w[3 * i + c] - v[c]).abs() < 1e-12);
        }
    }
}

#[test]
fn manufactured_solution_converges_at_order_one_on_tetrahedra() {
    // w* = (x²y, y²z, z²x); −div σ = −η Δw − (η + ξ) ∇ div w with Δw = 2(y, z, x) and
    // ∇ div w = 2(y + z, x + z, x + y).
    let (a, b) = (2.0 * ETA, 2.0 * (ETA + XI));
    let f = VectorField([
        formula(&format!("-{a}*y - {b}*(y + z)")),
        formula(&format!("-{a}*z - {b}*(x + z)")),
        formula(&format!("-{a}*x - {b}*(x + y)")),
    ]);
    let exact = |p: [f64; 3]| {
        let (x, y, z) = (p[0], p[1], p[2]);
        [x * x * y, y * y * z, z * z * x]
    };
    let eps = |p: [f64; 3]| {
        let (x, y, z) = (p[0], p[1], p[2]);
        [
            2.0 * x * y,
            2.0 * y * z,
            2.0 * z * x,
            0.5 * x * x,
            0.5 * y * y,
            0.5 * z * z,
        ]
    };
    let errors: Vec<f64> = [2, 4, 8, 16]
        .iter()
        .map(|&n| {
            let mesh = Mesh::cuboid(1.0, 1.0, 1.0, n, n, n);
            strain_error(&mesh, &dirichlet::solve(&mesh, (ETA, XI), &f, exact), eps)
        })
        .collect();
    let orders: Vec<f64> = errors.windows(2).map(|e| (e[0] / e[1]).log2()).collect();
    eprintln!("errors {errors:?}, orders {orders:?}");
    assert!(
        orders[1..].iter().all(|&o| (0.9..1.2).contains(&o)),
        "orders {orders:?}"
    );
}

fn rotate(v: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|r| (0..3).map(|c| BOX_ROTATION[r][c] * v[c]).sum())
}

/// The rotated box file, by name.
struct RotatedBox;

impl MeshFiles for RotatedBox {
    fn load(&self, name: &str) -> Result<AnyMesh, String> {
        assert_eq!(name, "box-rotated.msh");
        let bytes = std::fs::read(
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/meshes/box-rotated.msh"),
        )
        .unwrap();
        contact_core::mesh::import::import_any(&bytes).map_err(|e| e.to_string())
    }
}

/// box-exp3 at h = 1/4, k = 1/8, with a friction bound g = 2 under which part of Γ3 slips,
/// estimating its error a posteriori.
fn box_slipping() -> Value {
    let mut doc = presets::get("box-exp3").unwrap();
    doc["mesh"]["h"] = json!("1/4");
    doc["friction"] = json!({"law": "tresca", "g": 2});
    doc["output"] = json!({"estimate": true});
    doc
}

fn reports<const D: usize>(p: Problem) -> (Vec<StepReport>, Simulation<D>) {
    let mut out = Vec::new();
    let mut sim = Simulation::<D>::new(p, Default::default()).unwrap();
    while !sim.finished() {
        let r = sim.step().unwrap();
        invariants::check_step(&sim, &r).unwrap_or_else(|e| panic!("{e}"));
        out.push(r);
    }
    (out, sim)
}

/// The a posteriori estimate's parts of a step (velocity with friction, damage).
fn estimate_parts(r: &StepReport) -> Vec<(f64, &'static str)> {
    let e = r.estimate.expect("the scene asks for the estimate");
    let (v, d) = (e.velocity, e.damage.unwrap());
    vec![
        (v.element, "η element"),
        (v.jump, "η jump"),
        (v.traction, "η traction"),
        (v.friction, "η friction"),
        (v.time, "η time"),
        (d.element, "η damage element"),
        (d.jump, "η damage jump"),
        (d.time, "η damage time"),
    ]
}

#[test]
fn a_rotated_box_gives_the_same_norms_and_slips_obliquely() {
    let f2 = [-1.0, 0.0, -1.0];
    let (straight, _) = reports::<3>(scene::validate(&box_slipping()).unwrap());
    let mut doc = box_slipping();
    let g = rotate(f2);
    doc["domain"] = json!({"mesh": "box-rotated.msh"});
    doc["mesh"] = json!({"refine": 0});
    doc["boundary"] = json!([
        {"type": "clamped", "group": "clamped"},
        {"type": "contact", "group": "contact"},
        {"type": "traction", "group": "load", "f2": g},
    ]);
    let p = scene::validate_with(&doc, &RotatedBox).unwrap();
    let (rotated, sim) = reports::<3>(p);
    assert!(
        sim.dofs.frames.len() * 2 == sim.dofs.n_contact(),
        "every Γ3 node of the rotated box has a rotated frame"
    );
    assert!(straight.iter().any(|r| r.slip_nodes > 0), "Γ3 slips");
    assert!(
        straight
            .iter()
            .any(|r| r.estimate.unwrap().velocity.friction > 0.0),
        "the friction residual is exercised"
    );
    for (a, b) in straight.iter().zip(&rotated) {
        assert_eq!(a.slip_nodes, b.slip_nodes, "step {}", a.n);
        for (x, y, what) in [
            (a.w_v, b.w_v, "|w|_V"),
            (a.u_v, b.u_v, "|u|_V"),
            (a.zeta_l2, b.zeta_l2, "|ζ|_Z0"),
            (a.zeta_min, b.zeta_min, "min ζ"),
        ] {
            assert!(
                (x - y).abs() <= 1e-9 * x.abs().max(1e-300),
                "{what} at step {}: {x} vs {y}",
                a.n
            );
        }
        // Each part to 1e-9 of the step's whole estimate (a part may be 0 up to rounding).
        let total = a.estimate.unwrap().total;
        assert!(total > 0.0 && (total - b.estimate.unwrap().total).abs() <= 1e-9 * total);
        for ((x, what), (y, _)) in estimate_parts(a).into_iter().zip(estimate_parts(b)) {
            assert!(
                (x - y).abs() <= 1e-9 * total,
                "{what} at step {}: {x} vs {y}",
                a.n
            );
        }
    }
    // The slip direction in space is oblique: not along a coordinate axis.
    let slipping: Vec<[f64; 3]> = sim
        .contact_state()
        .iter()
        .filter(|c| c.slipping)
        .map(|c| c.tangential_velocity.unwrap())
        .collect();
    assert!(!slipping.is_empty());
    for v in &slipping {
        let n = v.iter().map(|a| a * a).sum::<f64>().sqrt();
        let largest = v.iter().fold(0.0f64, |m, a| m.max(a.abs()));
        assert!(largest < 0.99 * n, "oblique slip {v:?}");
    }
}

#[test]
fn box_scenes_keep_the_invariants_with_stick_and_slip() {
    for g in [20.0, 2.0, 0.0] {
        let mut doc = box_slipping();
        doc["friction"] = json!({"law": "tresca", "g": g});
        let (steps, sim) = reports::<3>(scene::validate(&doc).unwrap());
        let nodes = sim.dofs.n_contact() / 2;
        let slip = steps.last().unwrap().slip_nodes;
        match g {
            0.0 => assert_eq!(slip, nodes, "frictionless: every Γ3 node slips"),
            20.0 => assert_eq!(slip, 0, "g = 20 holds Γ3"),
            _ => assert!(slip > 0 && slip < nodes, "g = {g}: {slip} of {nodes} slip"),
        }
    }
    // A slip-weakening law within (2.31) as well.
    let mut doc = box_slipping();
    doc["friction"] = json!({"law": "slip_weakening", "mu0": 0.6, "mu1": 0.4, "alpha": 0.5});
    doc["smallness"] = json!("warn");
    let (steps, _) = reports::<3>(scene::validate(&doc).unwrap());
    assert!(steps.iter().any(|r| r.slip_nodes > 0));
}

#[test]
fn the_vtu_of_a_box_holds_tetrahedra_and_symmetric_tensors() {
    let mut doc = box_slipping();
    doc["time"]["k"] = json!("1/2");
    let (_, sim) = reports::<3>(scene::validate(&doc).unwrap());
    let f = sim.fields();
    let Some(Stress::Solid(sigma)) = &f.sigma else {
        panic!("3D stresses have 6 components")
    };
    assert_eq!(sigma.len(), sim.mesh.n_cells());
    let mut buf = Vec::new();
    // Raw arrays: the cell types are read below without zlib.
    write_vtu(
        &mut buf,
        &sim.mesh.nodes,
        sim.mesh.cells_flat(),
        &f,
        Compression::None,
    )
    .unwrap();
    let text = String::from_utf8(buf).unwrap();
    let doc = roxmltree::Document::parse(&text).unwrap();
    let piece = doc.descendants().find(|n| n.has_tag_name("Piece")).unwrap();
    assert_eq!(
        piece.attribute("NumberOfCells").unwrap(),
        sim.mesh.n_cells().to_string()
    );
    let names: Vec<&str> = doc
        .descendants()
        .filter(|n| n.has_tag_name("DataArray"))
        .filter_map(|n| n.attribute("Name"))
        .collect();
    for name in [
        "u",
        "w",
        "zeta",
        "contact_state",
        "slip_velocity",
        "sigma",
        "von_mises",
    ] {
        assert!(names.contains(&name), "{name} in {names:?}");
    }
    // The cell types decode to VTK_TETRA (10) everywhere.
    let types = doc
        .descendants()
        .find(|n| n.attribute("Name") == Some("types"))
        .unwrap();
    let b64 = types.text().unwrap().trim();
    let bytes = base64::engine::general_purpose::STANDARD
        .decode(b64)
        .unwrap();
    assert_eq!(bytes.len(), 8 + sim.mesh.n_cells());
    assert!(bytes[8..].iter().all(|&t| t == 10));
}

/// box-convergence at h = k = 1/n.
fn box_convergence_problem(n: usize) -> Problem {
    let mut doc = presets::get("box-convergence").unwrap();
    doc["mesh"]["h"] = json!(format!("1/{n}"));
    doc["time"]["k"] = json!(format!("1/{n}"));
    doc["output"] = json!({"every": 0, "last": false, "fields": []});
    scene::validate(&doc).unwrap()
}

/// box-convergence at h = k = 1/n, run to T.
fn box_convergence(n: usize) -> Simulation<3> {
    contact_core::run::run_to_end::<3>(box_convergence_problem(n), Default::default()).unwrap()
}

#[test]
fn the_3d_convergence_test_converges_at_order_one() {
    use contact_core::fem::{norms, prolongation::prolongate};
    let reference = box_convergence(16);
    let (mesh, geo) = (&reference.mesh, &reference.geo);
    let mass = assembly::mass(mesh, geo);
    let mut scratch = vec![0.0; mesh.n_nodes()];
    let w_ref = norms::strain_norm(mesh, geo, &reference.w);
    let z_ref = norms::mass_norm(&mass, &reference.state.zeta, &mut scratch);
    let mut rows = Vec::new();
    for n in [2, 4, 8] {
        let sim = box_convergence(n);
        let w = prolongate(&sim.mesh, &sim.w, 3, mesh).expect("nested boxes");
        let z = prolongate(&sim.mesh, &sim.state.zeta, 1, mesh).expect("nested boxes");
        let dw: Vec<f64> = reference.w.iter().zip(&w).map(|(a, b)| a - b).collect();
        let dz: Vec<f64> = reference
            .state
            .zeta
            .iter()
            .zip(&z)
            .map(|(a, b)| a - b)
            .collect();
        rows.push((
            n,
            norms::strain_norm(mesh, geo, &dw) / w_ref,
            norms::mass_norm(&mass, &dz, &mut scratch) / z_ref,
        ));
    }
    let order = |a: f64, b: f64| (a / b).log2();
    for r in &rows {
        eprintln!(
            "h = 1/{}: |w − w_ref|_V / |w_ref|_V = {:.3e}, |ζ − ζ_ref|_Z0 / |ζ_ref|_Z0 = {:.3e}",
            r.0, r.1, r.2
        );
    }
    let ow: Vec<f64> = rows.windows(2).map(|p| order(p[0].1, p[1].1)).collect();
    let oz: Vec<f64> = rows.windows(2).map(|p| order(p[0].2, p[1].2)).collect();
    eprintln!("orders w {ow:?}, ζ {oz:?}; |w_ref|_V = {w_ref}, |ζ_ref|_Z0 = {z_ref}");
    assert!(
        rows.windows(2).all(|p| p[1].1 < p[0].1 && p[1].2 < p[0].2),
        "{rows:?}"
    );
    // At h = k = 1/2 the velocity at T is exactly 0 (B = 2A at ζ = 1 with the paper's
    // moduli, so the load of step 2, f − B ε(k w_1) = f − 2k f, vanishes at k = 1/2): its error
    // is 1 and the first order is not asymptotic. The second is the one to read.
    assert!((0.8..1.4).contains(&ow[1]), "orders of w {ow:?}");
    assert!(oz.iter().all(|&o| o > 0.9), "orders of ζ {oz:?}");

    // The study service's table (strains taken on parent cells, no prolongation of w) is the
    // same numbers as the interpolation above.
    let problem = box_convergence_problem(16);
    let table = contact_core::study::run_ladder(&problem, &[(2, 2), (4, 4), (8, 8)], (16, 16))
        .expect("3D study");
    eprintln!("{}", table.text_table());
    assert!((table.reference.w_v - w_ref).abs() <= 1e-12 * w_ref);
    assert!((table.reference.zeta_z0 - z_ref).abs() <= 1e-12 * z_ref);
    for (row, r) in table.rows.iter().zip(&rows) {
        assert_eq!(row.h, 1.0 / r.0 as f64);
        assert!(
            (row.err_w - r.1).abs() <= 1e-9 * r.1,
            "{row:?} against {r:?}"
        );
        assert!(
            (row.err_zeta - r.2).abs() <= 1e-9 * r.2,
            "{row:?} against {r:?}"
        );
    }
}

#[test]
fn a_box_carries_an_error_estimate_from_the_nested_coarse_boxes() {
    let mut doc = presets::get("box-exp3").unwrap();
    doc["error_estimate"] = json!(true);
    doc["output"] = json!({"every": 0, "last": true, "fields": ["u"]});
    let summary = contact_core::run::run::<3>(
        scene::validate(&doc).unwrap(),
        Default::default(),
        |_, _| std::ops::ControlFlow::Continue(()),
    )
    .unwrap();
    let e = summary.error_estimate.expect("asked for");
    assert_eq!((e.coarse_h, e.coarse_k), (0.25, 0.25));
    assert!(e.check, "h = k = 1/8 also has the (4h, 4k) run");
    let last = e.final_.expect("an estimate at T");
    let w = last.w.unwrap();
    assert!(w > 0.0 && w < 0.5 && !last.flagged, "{last:?}");
}

/// A mesh file by name, from bytes made in the test.
struct Made(Vec<u8>);

impl MeshFiles for Made {
    fn load(&self, _: &str) -> Result<AnyMesh, String> {
        contact_core::mesh::import::import_any(&self.0).map_err(|e| e.to_string())
    }
}

/// The runs of an imported mesh compute on it renumbered for locality, and report on it as
/// given: box-exp3 at h = 1/4 (part of Γ3 slipping) on the generated box and on the same box
/// written to a file with its nodes and cells scrambled give the same fields node by node
/// and cell by cell through the scramble, the same Γ3 states and the same checkpoints, and
/// a checkpoint of the scrambled run continues it.
#[test]
fn a_scrambled_mesh_file_reports_in_its_own_numbering() {
    let mut doc = box_slipping();
    doc["output"] = json!({"every": 1, "fields": ["u", "w", "zeta", "sigma", "contact"]});
    doc["time"] = json!({"t_end": 0.25, "k": "1/16"});
    let generated = scene::validate(&doc).unwrap();
    let b = generated.mesh::<3>().unwrap();
    let (n, nc) = (b.n_nodes(), b.n_cells());
    // Permutations: 104729 and 7919 are primes that divide neither count.
    let label = |v: usize| (v * 104_729) % n;
    let cell_at = |e: usize| (e * 7_919) % nc; // the file's cell e is the box's cell_at(e)
    let mut nodes = vec![[0.0; 3]; n];
    for (v, p) in b.nodes.iter().enumerate() {
        nodes[label(v)] = *p;
    }
    let cells = (0..nc)
        .flat_map(|e| b.cell(cell_at(e)).iter().map(|&v| label(v)))
        .collect();
    let scrambled_mesh = Mesh::from_cells(nodes, cells).unwrap();
    let file = Made(contact_core::mesh::export::msh(&scrambled_mesh).into_bytes());
    doc["domain"] = json!({"mesh": "scrambled.msh"});
    doc["mesh"] = json!({"refine": 0});
    let scrambled = scene::validate_with(&doc, &file).unwrap();

    let mut a = Simulation::<3>::new(generated, Default::default()).unwrap();
    let mut s = Simulation::<3>::new(scrambled.clone(), Default::default()).unwrap();
    assert_eq!(s.output_mesh().nodes, scrambled_mesh.nodes);
    assert_ne!(
        s.mesh.nodes, scrambled_mesh.nodes,
        "the run renumbered the file's mesh"
    );
    let close = |x: f64, y: f64, scale: f64| (x - y).abs() <= 1e-9 * scale;
    let mut file_of_cell = vec![0; nc];
    for e in 0..nc {
        file_of_cell[cell_at(e)] = e;
    }
    let mut slipped = false;
    let mut checkpoint = None;
    while !a.finished() {
        a.step().unwrap();
        let r = s.step().unwrap();
        invariants::check_step(&s, &r).unwrap_or_else(|e| panic!("{e}"));
        let (fa, fs) = (a.fields(), s.fields());
        for (what, va, vs, width) in [
            ("u", fa.u.unwrap(), fs.u.unwrap(), 3),
            ("w", fa.w.unwrap(), fs.w.unwrap(), 3),
            ("ζ", fa.zeta.unwrap(), fs.zeta.unwrap(), 1),
        ] {
            let scale = va.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for v in 0..n {
                for c in 0..width {
                    let (x, y) = (va[width * v + c], vs[width * label(v) + c]);
                    assert!(close(x, y, scale), "{what} at node {v}: {x} vs {y}");
                }
            }
        }
        let (Some(Stress::Solid(sa)), Some(Stress::Solid(ss))) = (fa.sigma, fs.sigma) else {
            panic!("3D stresses")
        };
        let scale = sa.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
        for e in 0..nc {
            for (x, y) in sa[e].iter().zip(&ss[file_of_cell[e]]) {
                assert!(close(*x, *y, scale), "σ at cell {e}");
            }
        }
        // Γ3 nodes listed by increasing node of the file, with the box's states.
        let (ca, cs) = (fa.contact.unwrap(), fs.contact.unwrap());
        assert!(cs.windows(2).all(|w| w[0].node < w[1].node));
        let mut ca: Vec<_> = ca.into_iter().map(|c| (label(c.node), c)).collect();
        ca.sort_by_key(|c| c.0);
        assert_eq!(ca.len(), cs.len());
        for ((node, x), y) in ca.iter().zip(&cs) {
            assert_eq!((*node, x.slipping), (y.node, y.slipping));
            assert!(close(x.slip_velocity, y.slip_velocity, 1.0));
        }
        slipped |= cs.iter().any(|c| c.slipping);
        if r.n == 2 {
            checkpoint = Some(s.checkpoint_state());
            let (ka, ks) = (a.checkpoint_state(), s.checkpoint_state());
            for v in 0..n {
                assert_eq!(ka.damage_active[v], ks.damage_active[label(v)], "node {v}");
            }
            // The Γ3 warm start: two tangential values per node, nodes in the file's order.
            let nodes_a: Vec<usize> = a.dofs.contact.iter().step_by(2).map(|c| c.node).collect();
            let mut order: Vec<usize> = (0..nodes_a.len()).collect();
            order.sort_by_key(|&i| label(nodes_a[i]));
            for (j, &i) in order.iter().enumerate() {
                for c in 0..2 {
                    let (x, y) = (
                        ka.contact_velocity[2 * i + c],
                        ks.contact_velocity[2 * j + c],
                    );
                    assert!(close(x, y, 1.0), "warm start of Γ3 node {}", nodes_a[i]);
                }
            }
        }
    }
    assert!(slipped, "part of Γ3 slips");
    // Continued from the checkpoint of step 2, a fresh run ends where the first did.
    let mut resumed = Simulation::<3>::new(scrambled, Default::default()).unwrap();
    resumed.restore(checkpoint.unwrap());
    while !resumed.finished() {
        resumed.step().unwrap();
    }
    let (x, y) = (s.fields(), resumed.fields());
    for (p, q) in x.w.unwrap().iter().zip(&y.w.unwrap()) {
        assert!(close(*p, *q, 1.0), "{p} vs {q}");
    }
}
