//! `cargo bench --bench meshes`: the speed of any-shape bodies (issue 13's targets).
//!
//! 1. Import of a gmsh MSH 4.1 file of 1,000,000 triangles (ASCII and binary, written here
//!    from a structured 1000 × 500 mesh), against reading the bytes only.
//! 2. Polygon meshing of about 100,000 triangles (an L-shaped bracket with a hole).
//! 3. The time step on an unstructured mesh against a structured one with about the same
//!    number of unknowns (same solver, same fill-reducing ordering, same physics): paper-exp3
//!    on the 2 × 1 rectangle meshed by the polygon mesher against the generator's mesh of the
//!    same node count; the ratio is step time per unknown.
//!
//! Figures are the best of 3; set CONTACT_SIM_BENCH_QUICK=1 for a smaller import mesh.

use std::ops::ControlFlow;
use std::time::Instant;

use contact_core::mesh::{import, polygon, Mesh, MeshPattern};
use contact_core::msh;
use contact_core::run::{Run, ToEnd};
use contact_core::scene::{self, presets};
use contact_core::solve::SolverSettings;
use serde_json::json;

fn best<T>(repeat: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut out = None;
    let mut t = f64::INFINITY;
    for _ in 0..repeat {
        let s = Instant::now();
        let r = f();
        t = t.min(s.elapsed().as_secs_f64());
        out = Some(r);
    }
    (t, out.expect("repeat ≥ 1"))
}

/// An MSH 4.1 file of the mesh's triangles, one surface entity, no groups.
fn msh(m: &Mesh, binary: bool) -> Vec<u8> {
    let (n, c) = (m.n_nodes(), m.n_cells());
    let mut s: Vec<u8> = Vec::with_capacity(64 * (n + c));
    let ty = if binary { 1 } else { 0 };
    s.extend(format!("$MeshFormat\n4.1 {ty} 8\n").bytes());
    if binary {
        s.extend(1i32.to_le_bytes());
        s.push(b'\n');
    }
    s.extend(b"$EndMeshFormat\n$Entities\n");
    if binary {
        // Counts (size_t), then the surface: tag, bounding box, no physical tags, no curves.
        for v in [0u64, 0, 1, 0] {
            s.extend(v.to_le_bytes());
        }
        s.extend(1i32.to_le_bytes());
        for v in [0.0f64, 0.0, 0.0, 2.0, 1.0, 0.0] {
            s.extend(v.to_le_bytes());
        }
        s.extend(0u64.to_le_bytes());
        s.extend(0u64.to_le_bytes());
        s.extend(b"\n");
    } else {
        s.extend(b"0 0 1 0\n1 0 0 0 2 1 0 0 0\n");
    }
    s.extend(b"$EndEntities\n$Nodes\n");
    if binary {
        for v in [1u64, n as u64, 1, n as u64] {
            s.extend(v.to_le_bytes());
        }
        s.extend(2i32.to_le_bytes());
        s.extend(1i32.to_le_bytes());
        s.extend(0i32.to_le_bytes());
        s.extend((n as u64).to_le_bytes());
        (1..=n as u64).for_each(|t| s.extend(t.to_le_bytes()));
        for p in &m.nodes {
            for v in [p[0], p[1], 0.0] {
                s.extend(v.to_le_bytes());
            }
        }
        s.extend(b"\n$EndNodes\n$Elements\n");
        for v in [1u64, c as u64, 1, c as u64] {
            s.extend(v.to_le_bytes());
        }
        s.extend(2i32.to_le_bytes());
        s.extend(1i32.to_le_bytes());
        s.extend(2i32.to_le_bytes());
        s.extend((c as u64).to_le_bytes());
        for (e, t) in m.triangles().iter().enumerate() {
            s.extend((e as u64 + 1).to_le_bytes());
            t.iter()
                .for_each(|&v| s.extend((v as u64 + 1).to_le_bytes()));
        }
        s.extend(b"\n$EndElements\n");
    } else {
        s.extend(format!("1 {n} 1 {n}\n2 1 0 {n}\n").bytes());
        (1..=n).for_each(|t| s.extend(format!("{t}\n").bytes()));
        for p in &m.nodes {
            s.extend(format!("{:?} {:?} 0\n", p[0], p[1]).bytes());
        }
        s.extend(format!("$EndNodes\n$Elements\n1 {c} 1 {c}\n2 1 2 {c}\n").bytes());
        for (e, t) in m.triangles().iter().enumerate() {
            s.extend(format!("{} {} {} {}\n", e + 1, t[0] + 1, t[1] + 1, t[2] + 1).bytes());
        }
        s.extend(b"$EndElements\n");
    }
    s
}

/// Seconds per time step (best of 3 runs of `steps` steps after the set-up) and unknowns.
fn step_time(mut doc: serde_json::Value, steps: usize) -> (f64, usize, usize) {
    doc["time"] = json!({"t_end": 1, "N": steps});
    doc["output"] = json!({"every": 0, "last": false, "fields": []});
    let p = scene::validate(&doc).expect("scene");
    let mut t = f64::INFINITY;
    let mut sizes = (0, 0);
    for _ in 0..3 {
        let mut run = Run::<2>::new(p.clone(), SolverSettings::default()).expect("set-up");
        let s = Instant::now();
        let ControlFlow::Continue(()) = run.drive(&mut ToEnd).expect("step");
        t = t.min(s.elapsed().as_secs_f64());
        let sim = run.sim();
        sizes = (sim.dofs.n_free(), sim.mesh.n_nodes());
    }
    (t / steps as f64, sizes.0, sizes.1)
}

fn main() {
    let quick = std::env::var("CONTACT_SIM_BENCH_QUICK").is_ok();
    let (nx, ny) = if quick { (200, 100) } else { (1000, 500) };
    let m = Mesh::rectangle(2.0, 1.0, nx, ny, MeshPattern::Diagonal);
    println!(
        "import of {} triangles, {} nodes:",
        m.n_cells(),
        m.n_nodes()
    );
    for binary in [false, true] {
        let bytes = msh(&m, binary);
        let (read, file) = best(3, || msh::read(&bytes).expect("read"));
        let (check, mesh) = best(3, || import::from_msh::<2>(&file).expect("checks"));
        assert_eq!(mesh.n_cells(), m.n_cells());
        let kind = if binary { "binary" } else { "ASCII" };
        println!(
            "  {kind:6} {:6.1} MB: {:.3} s = read {read:.3} s + checks and boundary {check:.3} s ({:.0} ns per cell)",
            bytes.len() as f64 / 1e6,
            read + check,
            (read + check) / m.n_cells() as f64 * 1e9,
        );
    }

    let outer = [
        [0.0, 0.0],
        [2.0, 0.0],
        [2.0, 0.5],
        [1.0, 0.5],
        [1.0, 1.0],
        [0.0, 1.0],
    ];
    let hole = vec![[0.3, 0.3], [0.6, 0.3], [0.6, 0.6], [0.3, 0.6]];
    let h = 0.0073;
    let (t, tri) = best(3, || {
        polygon::triangulate(&outer, std::slice::from_ref(&hole), h, 2_000_000).expect("polygon")
    });
    println!(
        "polygon meshing: {} triangles, {} nodes in {t:.3} s (h = {h})",
        tri.triangles.len(),
        tri.nodes.len()
    );

    println!("time step of paper-exp3 (and with slip, g = 1) on the 2 × 1 rectangle meshed by the polygon mesher (unstructured) and by the generator with about the same node count:");
    for (hs, g, damage) in [
        ("1/32", 20, true),
        ("1/64", 20, true),
        ("1/64", 1, true),
        ("1/64", 20, false),
    ] {
        let mut u = presets::get("paper-exp3").expect("preset");
        u["domain"] = json!({"polygon": [[0, 0], [2, 0], [2, 1], [0, 1]]});
        u["mesh"] = json!({"h": hs});
        u["friction"]["g"] = json!(g);
        if !damage {
            u.as_object_mut().expect("scene").remove("damage");
        }
        let (tu, uu, nu) = step_time(u, 8);
        let cells = ((nu as f64 / 2.0).sqrt()).round() as usize;
        let mut r = presets::get("paper-exp3").expect("preset");
        r["mesh"]["h"] = json!(format!("1/{cells}"));
        r["friction"]["g"] = json!(g);
        if !damage {
            r.as_object_mut().expect("scene").remove("damage");
        }
        let (ts, us, ns) = step_time(r, 8);
        println!(
            "  g = {g:2}, damage {damage:5}: polygon h = {hs}: {nu} nodes, {uu} unknowns, {:.2} ms/step | generator 1/{cells}: {ns} nodes, {us} unknowns, {:.2} ms/step | per unknown: {:.2}×",
            tu * 1e3,
            ts * 1e3,
            (tu / uu as f64) / (ts / us as f64)
        );
    }
}
