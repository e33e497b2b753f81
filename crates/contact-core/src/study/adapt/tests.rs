use super::*;
use crate::study::target::Discard;

fn parse(doc: Value) -> Result<AdaptSpec, ValidationErrors> {
    parse_with(&doc, "/study", &scene::Bundled).map(|(s, _)| s)
}

fn pointer(doc: Value) -> String {
    parse(doc).unwrap_err().0[0].pointer.clone()
}

#[test]
fn bad_requests_name_their_field() {
    let ok = json!({"scene": "l-bracket", "adapt": {"target": 0.05}});
    assert!(parse(ok).is_ok());
    for (doc, at) in [
        (
            json!({"scene": "l-bracket", "adapt": {}}),
            "/study/adapt/target",
        ),
        (
            json!({"scene": "l-bracket", "adapt": {"target": 1.5}}),
            "/study/adapt/target",
        ),
        (
            json!({"scene": "l-bracket", "adapt": {"target": 0.1, "theta": 0}}),
            "/study/adapt/theta",
        ),
        (
            json!({"scene": "l-bracket", "adapt": {"target": 0.1, "quantity": "zeta"}}),
            "/study/adapt/quantity",
        ),
        (
            json!({"scene": "l-bracket", "adapt": {"target": 0.1, "max_nodes": 2.5}}),
            "/study/adapt/max_nodes",
        ),
        (
            json!({"scene": "l-bracket", "adapt": {"target": 0.1, "tagret": 1}}),
            "/study/adapt/tagret",
        ),
        (
            json!({"scene": "l-bracket", "adapt": {"target": 0.1}, "reference": {"refine": 0}}),
            "/study/reference/refine",
        ),
        (
            json!({"scene": "l-bracket", "adapt": {"target": 0.1}, "reference": {"h": "1/64"}}),
            "/study/reference/h",
        ),
        (
            json!({"scene": "l-bracket", "adapt": {"target": 0.1}, "h": ["1/4"]}),
            "/study/h",
        ),
        (
            json!({"scene": "no-such", "adapt": {"target": 0.1}}),
            "/study/scene",
        ),
        (
            json!({"scene": {"domain": {"width": -1}}, "adapt": {"target": 0.1}}),
            "/study/scene/domain/width",
        ),
    ] {
        assert_eq!(pointer(doc.clone()), at, "{doc}");
    }
}

/// The l-bracket on a coarse mesh with a short time interval: small enough for a unit test.
fn small_bracket(target: f64, max_cycles: usize, reference: Option<usize>) -> AdaptSpec {
    let mut scene = crate::scene::presets::get("l-bracket").unwrap();
    scene["mesh"]["h"] = json!("1/4");
    scene["time"] = json!({"t_end": 0.25, "k": "1/16"});
    scene["output"] = json!({"every": 0, "last": true, "fields": ["w"]});
    let mut doc = json!({"scene": scene, "adapt": {"target": target, "max_cycles": max_cycles, "max_nodes": 4000}});
    if let Some(r) = reference {
        doc["reference"] = json!({"refine": r});
    }
    parse(doc).unwrap()
}

/// The study on one thread, under the default limits, without progress or stored steps.
fn run_quietly(spec: &AdaptSpec) -> Result<AdaptResult, StudyError> {
    run(
        spec,
        exec(),
        Limits::default(),
        &|_, _| ControlFlow::Continue(()),
        &mut Discard,
    )
}

fn exec() -> Execution {
    Execution {
        threads: 1,
        settings: Default::default(),
    }
}

#[test]
fn cycles_refine_where_marked_and_the_estimate_falls() {
    let spec = small_bracket(1e-6, 4, Some(2));
    let r = run_quietly(&spec).unwrap();
    eprintln!("{}", r.text_table());
    assert_eq!(r.stopped, Stop::MaxCycles);
    assert!(!r.reached);
    assert_eq!(r.cycles.len(), 4);
    for w in r.cycles.windows(2) {
        assert!(w[1].nodes > w[0].nodes, "{:?}", r.cycles);
        assert!(w[1].estimate < w[0].estimate, "{:?}", r.cycles);
        // Dörfler with θ = 1/2 marks a minority of the cells on a mesh with a singularity.
        assert!(w[0].marked.unwrap() < w[0].cells);
    }
    // Every cycle is within the reference's depth 2·2, so each has a true error, and it falls.
    let errors: Vec<f64> = r.cycles.iter().map(|c| c.error.unwrap()).collect();
    assert!(errors.windows(2).all(|w| w[1] < w[0]), "{errors:?}");
    // The uniform line starts at the first cycle and stops before the reference's depth.
    assert_eq!(r.uniform[0].nodes, r.cycles[0].nodes);
    assert!(r.uniform.iter().all(|u| u.generation < 4));
    assert_eq!(r.summary.mesh.nodes, r.cycles[3].nodes);
    match &r.final_mesh {
        AnyMesh::Plane(m) => assert_eq!(m.n_nodes(), r.cycles[3].nodes),
        AnyMesh::Solid(_) => panic!("the bracket is plane"),
    }
}

#[test]
fn a_reachable_target_stops_the_cycles() {
    let first = run_quietly(&small_bracket(0.95, 1, None)).unwrap();
    assert_eq!(first.stopped, Stop::Target, "{}", first.text_table());
    assert!(first.reached && first.cycles.len() == 1);
    // A target between the first two cycles' estimates takes exactly two.
    let two = run_quietly(&small_bracket(1e-6, 2, None)).unwrap();
    let target = 0.5 * (two.cycles[0].estimate + two.cycles[1].estimate);
    let r = run_quietly(&small_bracket(target, 6, None)).unwrap();
    assert_eq!(
        (r.stopped, r.cycles.len()),
        (Stop::Target, 2),
        "{}",
        r.text_table()
    );
}

#[test]
fn the_node_budget_ends_the_cycles_before_it_is_passed() {
    let mut spec = small_bracket(1e-6, 40, None);
    spec.uniform = false;
    spec.max_nodes = Some(200);
    let r = run_quietly(&spec).unwrap();
    assert_eq!(r.stopped, Stop::MaxNodes);
    assert!(r.cycles.iter().all(|c| c.nodes <= 200));
    assert_eq!(r.uniform.len(), 1);
}

#[test]
fn the_reference_is_admitted_at_its_pointer() {
    let spec = small_bracket(0.1, 3, Some(6));
    let limits = Limits {
        max_nodes: Some(20_000),
        ..Limits::default()
    };
    let e = spec.admit(&limits, "/study").unwrap_err();
    assert_eq!(e.pointer, "/study/reference/refine");
    let mut spec = small_bracket(0.1, 3, None);
    spec.max_nodes = Some(50_000);
    assert_eq!(
        spec.admit(&limits, "/study").unwrap_err().pointer,
        "/study/adapt/max_nodes"
    );
}

#[test]
fn a_dominant_time_part_ends_the_cycles() {
    // With k = T/2 the time part overtakes the spatial parts after a few cycles; refining
    // the mesh further would not bring the estimate down.
    let mut scene = small_bracket(1e-6, 40, None).scene;
    scene["time"] = json!({"t_end": 1, "k": "1/2"});
    let spec = parse(json!({"scene": scene, "adapt": {"target": 1e-6, "max_cycles": 40, "max_nodes": 20000, "uniform": false}})).unwrap();
    let r = run_quietly(&spec).unwrap();
    assert_eq!(r.stopped, Stop::TimeStep, "{}", r.text_table());
    let (last, before) = r.cycles.split_last().unwrap();
    assert!(last.time_share > std::f64::consts::FRAC_1_SQRT_2);
    assert!(before
        .iter()
        .all(|c| c.time_share <= std::f64::consts::FRAC_1_SQRT_2));
    assert!(!before.is_empty());
}

/// With the spatial goal (a target study's comparison) the target bounds the estimate's
/// spatial part, √(estimate² − time part²), and a dominant time part does not end the cycles.
#[test]
fn the_spatial_goal_leaves_the_time_part_out() {
    let mut scene = small_bracket(1e-6, 40, None).scene;
    scene["time"] = json!({"t_end": 1, "k": "1/2"});
    let mut spec = parse(json!({"scene": scene, "adapt": {"target": 1e-6, "max_cycles": 8, "max_nodes": 20000, "uniform": false}})).unwrap();
    spec.spatial = true;
    let all = run_quietly(&spec).unwrap();
    assert_eq!(all.stopped, Stop::MaxCycles, "{}", all.text_table());
    assert!(all.cycles[7].time_share > std::f64::consts::FRAC_1_SQRT_2);
    for c in &all.cycles {
        let (space, time) = (c.space_estimate(), c.estimate * c.time_share);
        assert!((space * space + time * time - c.estimate * c.estimate).abs() <= 1e-12);
    }
    // The third cycle's spatial part as the target: reached there, although the whole
    // estimate is larger.
    spec.target = all.cycles[2].space_estimate();
    let three = run_quietly(&spec).unwrap();
    assert_eq!((three.stopped, three.cycles.len()), (Stop::Target, 3));
    assert!(three.cycles[2].estimate > spec.target);
}

/// The final mesh, exported and read back as an uploaded mesh would be.
struct Uploaded(Vec<u8>);

impl scene::MeshFiles for Uploaded {
    fn load(&self, _: &str) -> Result<AnyMesh, String> {
        crate::mesh::import::import_any(&self.0).map_err(|e| e.to_string())
    }
}

/// [`AdaptSpec::scene_on`] the exported final mesh validates, on rectangles, boxes, polygons
/// and imported meshes alike, and runs on the same nodes, cells and boundary parts.
#[test]
fn the_scene_on_the_final_mesh_validates_for_every_kind_of_body() {
    for (preset, mesh) in [
        ("paper-exp3", json!({"h": "1/4"})),
        ("l-bracket", json!({"h": "1/4"})),
        ("plate-with-hole", json!({"refine": 0})),
        ("box-exp3", json!({"h": "1/2"})),
    ] {
        let mut scene = crate::scene::presets::get(preset).unwrap();
        scene["mesh"] = mesh;
        scene["time"] = json!({"t_end": 0.125, "k": "1/16"});
        let spec = parse(
            json!({"scene": scene, "adapt": {"target": 1e-6, "max_cycles": 2, "uniform": false}}),
        )
        .unwrap();
        let r = run_quietly(&spec).unwrap();
        let files = Uploaded(r.final_msh().into_bytes());
        let p = scene::validate_with(&spec.scene_on("final"), &files)
            .unwrap_or_else(|e| panic!("{preset}: {e}"));
        let (again, before) = (p.any_mesh().unwrap(), &r.final_mesh);
        assert_eq!(again.n_nodes(), before.n_nodes(), "{preset}");
        assert_eq!(again.n_cells(), before.n_cells(), "{preset}");
        let parts = |m: &AnyMesh| -> Vec<Option<usize>> {
            let mut v: Vec<(Vec<usize>, Option<usize>)> = match m {
                AnyMesh::Plane(m) => m
                    .facets
                    .iter()
                    .map(|f| (sorted(&f.nodes), f.part))
                    .collect(),
                AnyMesh::Solid(m) => m
                    .facets
                    .iter()
                    .map(|f| (sorted(&f.nodes), f.part))
                    .collect(),
            };
            v.sort();
            v.into_iter().map(|(_, p)| p).collect()
        };
        assert_eq!(parts(&again), parts(before), "{preset}: boundary parts");
    }
}

fn sorted(nodes: &[usize]) -> Vec<usize> {
    let mut v = nodes.to_vec();
    v.sort_unstable();
    v
}

/// Levels are earlier cycles at least 2^d times coarser, down to the initial mesh, with the
/// midpoints made in between.
#[test]
fn multigrid_levels_are_earlier_cycles_2_to_the_d_times_coarser() {
    let initial = Mesh::<2>::rectangle(1.0, 1.0, 2, 2, crate::mesh::MeshPattern::Diagonal);
    let n0 = initial.n_nodes(); // 9
    let sizes = [n0, 14, 20, 37, 60, 90, 150];
    let mids: Vec<[usize; 2]> = (n0..150).map(|k| [k - 1, k - 2]).collect();
    let l = levels(&initial, &mids, &sizes);
    // 150 → the largest ≤ 150/4 is 37 → the largest ≤ 9.25 is 9 (the initial mesh).
    let coarse: Vec<usize> = l.iter().map(|n| n.coarse_nodes).collect();
    assert_eq!(coarse, [9, 37]);
    assert_eq!(l[0].midpoints, mids[..37 - 9]);
    assert_eq!(l[1].midpoints, mids[37 - 9..]);
    assert!(levels(&initial, &mids[..5], &sizes[..2]).is_empty());
}
