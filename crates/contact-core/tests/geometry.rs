//! Any body shape (docs/src/explanation/numerics.md#meshes, #contact-frames): an imported copy of a rectangle
//! mesh gives the built-in results; a rotated copy of a scene gives the same norms (its Γ3
//! is inclined, so every contact node has a rotated frame); a curved Γ3 keeps the run
//! invariants; boundary parts selected by formulas equal the same parts given as segments.

mod common;
use common::*;
use contact_core::mesh::{Mesh, MeshPattern};
use contact_core::problem::Problem;
use contact_core::scene::{self, presets, MeshFiles};
use contact_core::solve::invariants;
use contact_core::solve::stepper::{Simulation, StepReport};
use serde_json::{json, Value};

/// An ASCII MSH 4.1 file: 2D nodes, triangles (surface group "body") and named line groups.
fn msh(nodes: &[[f64; 2]], tris: &[[usize; 3]], groups: &[(&str, Vec<[usize; 2]>)]) -> String {
    let mut s = String::from("$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$PhysicalNames\n");
    s += &format!("{}\n", groups.len() + 1);
    for (i, (name, _)) in groups.iter().enumerate() {
        s += &format!("1 {} \"{name}\"\n", i + 1);
    }
    s += "2 100 \"body\"\n$EndPhysicalNames\n$Entities\n";
    s += &format!("0 {} 1 0\n", groups.len());
    for i in 0..groups.len() {
        s += &format!("{} 0 0 0 0 0 0 1 {} 0\n", i + 1, i + 1);
    }
    s += "1 0 0 0 0 0 0 1 100 0\n$EndEntities\n$Nodes\n";
    let n = nodes.len();
    s += &format!("1 {n} 1 {n}\n2 1 0 {n}\n");
    for i in 0..n {
        s += &format!("{}\n", i + 1);
    }
    for p in nodes {
        s += &format!("{:e} {:e} 0\n", p[0], p[1]);
    }
    let lines: usize = groups.iter().map(|g| g.1.len()).sum();
    let total = lines + tris.len();
    s += &format!(
        "$EndNodes\n$Elements\n{} {total} 1 {total}\n",
        groups.len() + 1
    );
    let mut tag = 1;
    for (i, (_, edges)) in groups.iter().enumerate() {
        s += &format!("1 {} 1 {}\n", i + 1, edges.len());
        for e in edges {
            s += &format!("{tag} {} {}\n", e[0] + 1, e[1] + 1);
            tag += 1;
        }
    }
    s += &format!("2 1 2 {}\n", tris.len());
    for t in tris {
        s += &format!("{tag} {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
        tag += 1;
    }
    s + "$EndElements\n"
}

/// One in-memory mesh file.
struct OneFile(String);

impl MeshFiles for OneFile {
    fn load(&self, name: &str) -> Result<contact_core::mesh::AnyMesh, String> {
        assert_eq!(name, "body.msh");
        contact_core::mesh::import::import_any(self.0.as_bytes()).map_err(|e| e.to_string())
    }
}

/// Experiment 3 on the 2×1 rectangle at h = k = 1/8, with g = 1 so that Γ3 slips.
fn exp3_slipping() -> Value {
    let mut doc = presets::get("paper-exp3").unwrap();
    doc["mesh"]["h"] = json!("1/8");
    doc["time"]["k"] = json!("1/8");
    doc["friction"] = json!({"law": "tresca", "g": 1});
    doc
}

/// The built-in 16 × 8 rectangle mesh of [`exp3_slipping`], its nodes mapped by `map`,
/// as a gmsh file with the groups clamped (x = 0), contact (y = 0) and loaded (top, right).
fn rectangle_file(map: impl Fn([f64; 2]) -> [f64; 2]) -> String {
    let m = Mesh::rectangle(2.0, 1.0, 16, 8, MeshPattern::Diagonal);
    let side = |on: &dyn Fn([f64; 2]) -> bool| -> Vec<[usize; 2]> {
        m.facets
            .iter()
            .filter(|f| f.nodes.iter().all(|&i| on(m.nodes[i])))
            .map(|f| f.nodes)
            .collect()
    };
    let groups = [
        ("clamped", side(&|p| p[0] == 0.0)),
        ("contact", side(&|p| p[1] == 0.0)),
        ("loaded", side(&|p| p[1] == 1.0 || p[0] == 2.0)),
    ];
    let nodes: Vec<_> = m.nodes.iter().map(|&p| map(p)).collect();
    msh(&nodes, m.triangles(), &groups)
}

/// [`exp3_slipping`] on the imported mesh file, parts bound to its groups, f2 given.
fn imported(file: String, f2: [f64; 2]) -> Problem {
    let mut doc = exp3_slipping();
    doc["domain"] = json!({"mesh": "body.msh"});
    doc["mesh"] = json!({"refine": 0});
    doc["boundary"] = json!([
        {"type": "clamped", "group": "clamped"},
        {"type": "traction", "group": "loaded", "f2": f2},
        {"type": "contact", "group": "contact"}
    ]);
    scene::validate_with(&doc, &OneFile(file)).unwrap_or_else(|e| panic!("{e}"))
}

fn reports(p: Problem) -> Vec<StepReport> {
    let mut out = Vec::new();
    run_checked(p, |sim, r| {
        invariants::check_step(sim, r).unwrap_or_else(|e| panic!("{e}"));
        out.push(r.clone());
    });
    out
}

fn assert_same_norms(a: &[StepReport], b: &[StepReport], tol: f64) {
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(b) {
        for (what, u, v) in [
            ("|w|_V", x.w_v, y.w_v),
            ("|u|_V", x.u_v, y.u_v),
            ("|ζ|_Z0", x.zeta_l2, y.zeta_l2),
            ("min ζ", x.zeta_min, y.zeta_min),
        ] {
            assert!(rel(u, v) <= tol, "step {}: {what} {u} vs {v}", x.n);
        }
    }
}

#[test]
fn an_imported_copy_of_the_rectangle_gives_the_built_in_results() {
    let builtin = reports(scene::validate(&exp3_slipping()).unwrap());
    assert!(
        builtin.iter().any(|r| r.slip_nodes > 0),
        "the scene must slip"
    );
    let copy = reports(imported(rectangle_file(|p| p), [-1.0, -1.0]));
    assert_same_norms(&builtin, &copy, 1e-12);
}

#[test]
fn a_rotated_copy_gives_the_same_norms() {
    let builtin = reports(scene::validate(&exp3_slipping()).unwrap());
    for (theta, centre) in [(0.7f64, [0.3, -1.2]), (2.0, [5.0, 1.0]), (-0.3, [0.0, 0.0])] {
        let (c, s) = (theta.cos(), theta.sin());
        let rot = |v: [f64; 2]| [c * v[0] - s * v[1], s * v[0] + c * v[1]];
        let map = |p: [f64; 2]| {
            let q = rot([p[0] - centre[0], p[1] - centre[1]]);
            [q[0] + centre[0], q[1] + centre[1]]
        };
        let p = imported(rectangle_file(map), rot([-1.0, -1.0]));
        let rotated = reports(p);
        assert!(rotated.iter().any(|r| r.slip_nodes > 0));
        assert_same_norms(&builtin, &rotated, 1e-9);
    }
}

#[test]
fn the_arch_slips_on_its_curved_support_and_keeps_the_invariants() {
    let p = scene::validate(&presets::get("arch-on-support").unwrap()).unwrap();
    let mut sim_frames = 0;
    let sim = run_checked(p, |sim, r| {
        invariants::check_step(sim, r).unwrap_or_else(|e| panic!("{e}"));
        sim_frames = sim.dofs.frames.len();
    });
    assert!(sim_frames > 10, "the inner arc's nodes have rotated frames");
    // n_i is the outward normal of the inner arc r = 1: −x/|x|, to O(h²) of the chords.
    for &(i, n) in &sim.dofs.normals {
        let p = sim.mesh.nodes[i];
        let r = p[0].hypot(p[1]);
        assert!((r - 1.0).abs() < 1e-9, "node {i} is on the arc");
        let angle = p[1].atan2(p[0]).to_degrees();
        if (angle - 120.0).abs() < 1e-6 {
            continue; // the free end: one Γ3 facet, its chord's normal
        }
        let radial = [-p[0] / r, -p[1] / r];
        let err = (n[0] - radial[0]).hypot(n[1] - radial[1]);
        assert!(err < 1e-2, "node {i}: n = {n:?}, radial {radial:?}");
    }
    assert!(sim.state.step == sim.problem.steps);
}

#[test]
fn formula_parts_equal_segment_parts() {
    let seg = scene::validate(&presets::get("paper-exp2").unwrap()).unwrap();
    let mut doc = presets::get("paper-exp2").unwrap();
    let parts = doc["boundary"].as_array_mut().unwrap();
    let contact = parts.iter().position(|p| p["type"] == "contact").unwrap();
    parts[contact] = json!({"type": "contact", "on": "y", "where": "1 - x"});
    let on = scene::validate(&doc).unwrap();
    let (a, b) = (seg.mesh().unwrap(), on.mesh().unwrap());
    let tags = |m: &Mesh| m.facets.iter().map(|f| f.part).collect::<Vec<_>>();
    assert_eq!(tags(&a), tags(&b));
}

#[test]
fn parts_that_select_badly_are_refused_at_their_pointer() {
    let base = presets::get("plate-with-hole").unwrap();
    let cases = [
        (
            json!({"type": "contact", "group": "nope"}),
            "/boundary/1",
            "\"hole\"",
        ),
        (
            json!({"type": "contact", "on": "y + 5"}),
            "/boundary/1",
            "selects no boundary facet",
        ),
        (
            json!({"type": "contact", "on": "x"}),
            "/boundary/1",
            "parts 0 and 1",
        ),
    ];
    for (part, ptr, text) in cases {
        let mut doc = base.clone();
        doc["boundary"][1] = part;
        let errs = scene::validate(&doc).unwrap_err().0;
        assert!(
            errs.iter()
                .any(|e| e.pointer == ptr && e.message.contains(text)),
            "{errs:?}"
        );
    }
}

/// plate-with-hole at k = 1/8 and `refine` red refinements.
fn plate(refine: u64) -> Problem {
    let mut doc = presets::get("plate-with-hole").unwrap();
    doc["time"]["k"] = json!("1/8");
    doc["mesh"]["refine"] = json!(refine);
    scene::validate(&doc).unwrap()
}

#[test]
fn a_study_of_a_given_mesh_refines_it_and_converges_at_order_one() {
    use contact_core::study::{run_ladder, spec};
    // Levels n = 2^refine (spec::resolution): refine 0, 1, 2 against refine 3.
    let base = plate(3);
    assert_eq!(spec::resolution(&base), 8);
    let s = run_ladder(&base, &[(1, 8), (2, 8), (4, 8)], (8, 8)).unwrap();
    eprintln!("{}", s.text_table());
    assert!(s
        .rows
        .windows(2)
        .all(|w| w[1].err_w < w[0].err_w && w[1].err_zeta < w[0].err_zeta));
    let ow: Vec<f64> = s.rows.iter().filter_map(|r| r.order_w).collect();
    assert!(
        ow.iter().all(|&o| (0.6..1.6).contains(&o)),
        "w orders {ow:?}"
    );

    // The study document names refine levels; h is refused for a given mesh.
    let doc = json!({"scene": "plate-with-hole", "refine": [0, 1], "k": "1/8",
                     "reference": {"refine": 2, "k": "1/8"}});
    let (plan, _) = spec::parse(&doc, "/study").unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(
        (plan.levels.clone(), plan.reference),
        (vec![(1, 8), (2, 8)], (4, 8))
    );
    let bad = json!({"scene": "plate-with-hole", "refine": [3], "k": "1/8",
                     "reference": {"refine": 2, "k": "1/8"}});
    let e = spec::parse(&bad, "/study").unwrap_err().0;
    assert!(e.iter().any(|e| e.pointer == "/study/refine/0"), "{e:?}");
    let h = json!({"scene": "plate-with-hole", "h": "1/4", "k": "1/8",
                   "reference": {"h": "1/8", "k": "1/8"}});
    let e = spec::parse(&h, "/study").unwrap_err().0;
    assert!(
        e.iter().any(|e| e.message.contains("give refine, not h")),
        "{e:?}"
    );
}

#[test]
fn the_error_estimate_of_a_given_mesh_uses_one_refinement_less() {
    // k = 1/32, so that the (4h, 4k) run's k = 1/8 stays far from k = 1/2 (kμ/η = 1).
    let mut doc = presets::get("plate-with-hole").unwrap();
    doc["error_estimate"] = json!(true);
    let e = scene::validate(&doc).unwrap_err().0;
    assert!(
        e.iter()
            .any(|e| e.pointer == "/error_estimate" && e.message.contains("refine ≥ 1")),
        "{e:?}"
    );
    doc["mesh"]["refine"] = json!(2);
    let p = scene::validate(&doc).unwrap();
    let out = contact_core::run::run::<2>(p, Default::default(), |_, _| {
        std::ops::ControlFlow::Continue(())
    })
    .unwrap();
    let est = out.error_estimate.expect("an estimate");
    let last = est.final_.expect("at T");
    // The (2h, 2k) difference is a relative error of a few percent, and the (4h, 4k) run
    // gives an observed order near 1.
    let w = last.w.unwrap();
    assert!(w > 1e-4 && w < 0.5, "{w}");
    let o = last.observed_order_w.unwrap();
    assert!((0.5..2.0).contains(&o), "{o}");
}

#[test]
fn the_given_mesh_presets_slip_in_part_and_keep_the_invariants() {
    for name in ["plate-with-hole", "l-bracket"] {
        let mut doc = presets::get(name).unwrap();
        doc["time"]["k"] = json!("1/8");
        let p = scene::validate(&doc).unwrap();
        let mut most = 0;
        let sim = run_checked(p, |sim, r| {
            invariants::check_step(sim, r).unwrap_or_else(|e| panic!("{name}: {e}"));
            most = most.max(r.slip_nodes);
        });
        let contact = sim.dofs.n_contact();
        assert!(
            most > 0 && most < contact,
            "{name}: {most} of {contact} Γ3 nodes slip"
        );
    }
}

#[test]
fn the_discrete_trace_constant_is_the_same_in_a_rotated_frame() {
    // A non-convex law makes the set-up compute cτ and the discrete strong-convexity margin
    // from the Schur complement onto the (rotated) contact DOFs.
    let law = json!({"law": "slip_weakening", "mu0": 1, "mu1": 0.5, "alpha": 0.5});
    let with_law = || {
        let mut doc = exp3_slipping();
        doc["friction"] = law.clone();
        doc
    };
    let builtin =
        Simulation::<2>::new(scene::validate(&with_law()).unwrap(), Default::default()).unwrap();
    let (c, s) = (0.9f64.cos(), 0.9f64.sin());
    let rot = |v: [f64; 2]| [c * v[0] - s * v[1], s * v[0] + c * v[1]];
    let mut doc = with_law();
    doc["domain"] = json!({"mesh": "body.msh"});
    doc["mesh"] = json!({"refine": 0});
    doc["boundary"] = json!([
        {"type": "clamped", "group": "clamped"},
        {"type": "traction", "group": "loaded", "f2": rot([-1.0, -1.0])},
        {"type": "contact", "group": "contact"}
    ]);
    let p = scene::validate_with(&doc, &OneFile(rectangle_file(rot))).unwrap();
    let rotated = Simulation::<2>::new(p, Default::default()).unwrap();
    assert!(rotated.dofs.frames.len() == rotated.dofs.n_contact());
    let (a, b) = (&builtin.smallness, &rotated.smallness);
    let (ca, cb) = (a.c_tau.unwrap(), b.c_tau.unwrap());
    assert!(rel(ca, cb) < 1e-9, "cτ {ca} vs {cb}");
    let (ma, mb) = (a.discrete_margin.unwrap(), b.discrete_margin.unwrap());
    assert!(
        (ma - mb).abs() < 1e-9 * ma.abs().max(1.0),
        "margin {ma} vs {mb}"
    );
    assert_eq!(a.holds, b.holds);
}
