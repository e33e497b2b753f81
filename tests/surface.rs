//! The boundary surface of a 3D result over real HTTP: `GET /jobs/{id}/fields?surface=1`
//! (with and without `mesh=1`, with `fields=` and `step=`) and `GET /jobs/{id}/mesh?surface=1`
//! have the counts of the box's lattice and the full field's values at the mapped nodes and
//! owning tetrahedra; a 2D job's answers are the whole ones; a bad flag is a 400 naming it.

use contact_sim::Config;
use serde_json::{json, Value};
use std::path::PathBuf;
use std::time::Duration;

mod common;
use common::http::{assert_problem, get, post_json, wait_status};
use common::server::Server;

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("contact-sim-surface-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn submit(addr: std::net::SocketAddr, preset: &str, h: &str) -> String {
    let mut scene = contact_core::scene::presets::get(preset).unwrap();
    scene["mesh"]["h"] = json!(h);
    scene["time"] = json!({"t_end": 0.5, "N": 2});
    let r = post_json(addr, "/jobs", &scene);
    assert_eq!(r.status, 202, "{}", r.text());
    let id = r.json()["id"].as_str().unwrap().to_string();
    let job = wait_status(
        addr,
        &id,
        &["succeeded", "failed"],
        Duration::from_secs(120),
    );
    assert_eq!(job["status"], "succeeded", "{job}");
    id
}

fn f64s(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn usizes(v: &Value) -> Vec<usize> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_u64().unwrap() as usize)
        .collect()
}

#[test]
fn a_3d_jobs_surface_has_the_lattice_counts_and_the_full_fields_values() {
    let dir = temp_dir("3d");
    let srv = Server::start_with(Config {
        data_dir: dir.clone(),
        workers: 1,
        max_nodes: 20_000,
        ..Config::default()
    });
    let a = srv.addr;
    // box-exp3 is (0,2)×(0,1)×(0,1): at h = 1/4, 8×4×4 cubes.
    let id = submit(a, "box-exp3", "1/4");
    let (nx, ny, nz) = (8usize, 4usize, 4usize);
    let all_nodes = (nx + 1) * (ny + 1) * (nz + 1);
    let tets = 6 * nx * ny * nz;
    // Two triangles per boundary square; every node but the interior ones.
    let triangles = 4 * (nx * ny + ny * nz + nz * nx);
    let surface_nodes = all_nodes - (nx - 1) * (ny - 1) * (nz - 1);

    let full = get(a, &format!("/jobs/{id}/fields?mesh=1&step=last")).json();
    let r = get(a, &format!("/jobs/{id}/fields?mesh=1&surface=1&step=last"));
    assert_eq!(r.status, 200, "{}", r.text());
    let surf = r.json();
    assert_eq!(full["mesh"]["nodes"].as_array().unwrap().len(), all_nodes);
    assert_eq!(full["mesh"]["tetrahedra"].as_array().unwrap().len(), tets);

    let m = &surf["mesh"];
    assert_eq!(m["dim"], 3);
    assert_eq!(m["surface"], true);
    assert!(m.get("tetrahedra").is_none());
    let ids = usizes(&m["node_ids"]);
    let tris: Vec<Vec<usize>> = m["triangles"]
        .as_array()
        .unwrap()
        .iter()
        .map(usizes)
        .collect();
    let cells = usizes(&m["cells"]);
    assert_eq!(ids.len(), surface_nodes);
    assert_eq!(m["nodes"].as_array().unwrap().len(), surface_nodes);
    assert_eq!(tris.len(), triangles);
    assert_eq!(cells.len(), triangles);
    assert_eq!(m["triangle_parts"].as_array().unwrap().len(), triangles);
    assert_eq!(m["parts"], full["mesh"]["parts"]);

    // The surface nodes are the nodes on a face of the box, at their coordinates.
    let full_nodes: Vec<Vec<f64>> = full["mesh"]["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(f64s)
        .collect();
    let size = [2.0, 1.0, 1.0];
    let on_box: Vec<usize> = (0..all_nodes)
        .filter(|&k| (0..3).any(|c| full_nodes[k][c] == 0.0 || full_nodes[k][c] == size[c]))
        .collect();
    assert_eq!(ids, on_box);
    for (i, p) in m["nodes"].as_array().unwrap().iter().enumerate() {
        assert_eq!(f64s(p), full_nodes[ids[i]]);
    }
    // Each triangle is a boundary face of the full mesh, on the tetrahedron named with it,
    // with the part the full mesh gives that face.
    let full_tets: Vec<Vec<usize>> = full["mesh"]["tetrahedra"]
        .as_array()
        .unwrap()
        .iter()
        .map(usizes)
        .collect();
    let key = |t: &[usize]| {
        let mut k = t.to_vec();
        k.sort_unstable();
        k
    };
    let full_faces: std::collections::HashMap<Vec<usize>, (Value, usize)> = full["mesh"]
        ["boundary_faces"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            (
                key(&usizes(&f[0])),
                (f[1].clone(), f[2].as_u64().unwrap() as usize),
            )
        })
        .collect();
    for (t, tri) in tris.iter().enumerate() {
        let original: Vec<usize> = tri.iter().map(|&k| ids[k]).collect();
        assert!(original.iter().all(|n| full_tets[cells[t]].contains(n)));
        let (part, cell) = &full_faces[&key(&original)];
        assert_eq!(*cell, cells[t]);
        assert_eq!(&m["triangle_parts"][t], part);
    }

    // The fields: the full ones at the mapped nodes and owning tetrahedra.
    let (fu, su) = (f64s(&full["u"]), f64s(&surf["u"]));
    let (fw, sw) = (f64s(&full["w"]), f64s(&surf["w"]));
    assert_eq!(su.len(), 3 * surface_nodes);
    for (i, &n) in ids.iter().enumerate() {
        assert_eq!(su[3 * i..3 * i + 3], fu[3 * n..3 * n + 3]);
        assert_eq!(sw[3 * i..3 * i + 3], fw[3 * n..3 * n + 3]);
        assert_eq!(surf["zeta"][i], full["zeta"][n]);
    }
    assert_eq!(surf["von_mises"].as_array().unwrap().len(), triangles);
    assert_eq!(surf["sigma"].as_array().unwrap().len(), triangles);
    for (t, &e) in cells.iter().enumerate() {
        assert_eq!(surf["von_mises"][t], full["von_mises"][e]);
        assert_eq!(surf["sigma"][t], full["sigma"][e]);
    }
    let (fc, sc) = (
        full["contact"].as_array().unwrap(),
        surf["contact"].as_array().unwrap(),
    );
    assert!(!fc.is_empty());
    assert_eq!(fc.len(), sc.len());
    for (f, s) in fc.iter().zip(sc) {
        assert_eq!(ids[s["node"].as_u64().unwrap() as usize] as u64, f["node"]);
        assert_eq!(s["slip_velocity"], f["slip_velocity"]);
        assert_eq!(s["traction"], f["traction"]);
    }
    assert_eq!(
        (surf["n"].clone(), surf["t"].clone()),
        (full["n"].clone(), full["t"].clone())
    );

    // Without the mesh, with a field list and another step: the same restriction.
    let r = get(
        a,
        &format!("/jobs/{id}/fields?surface=true&fields=zeta,von_mises&step=1"),
    );
    assert_eq!(r.status, 200, "{}", r.text());
    let s1 = r.json();
    let f1 = get(
        a,
        &format!("/jobs/{id}/fields?fields=zeta,von_mises&step=1"),
    )
    .json();
    assert!(s1.get("mesh").is_none() && s1.get("u").is_none());
    assert_eq!(s1["n"], 1);
    for (i, &n) in ids.iter().enumerate() {
        assert_eq!(s1["zeta"][i], f1["zeta"][n]);
    }
    for (t, &e) in cells.iter().enumerate() {
        assert_eq!(s1["von_mises"][t], f1["von_mises"][e]);
    }
    // surface=0 is the whole field.
    let s0 = get(
        a,
        &format!("/jobs/{id}/fields?surface=0&fields=zeta&step=1"),
    )
    .json();
    assert_eq!(s0["zeta"].as_array().unwrap().len(), all_nodes);

    // /mesh?surface=1 is the fields' surface mesh; /mesh alone the whole mesh.
    let r = get(a, &format!("/jobs/{id}/mesh?surface=1"));
    assert_eq!(r.status, 200, "{}", r.text());
    assert_eq!(r.json(), surf["mesh"]);
    assert_eq!(get(a, &format!("/jobs/{id}/mesh")).json(), full["mesh"]);

    // The surface is what a client draws of a solid: far smaller than the whole.
    let whole = get(a, &format!("/jobs/{id}/fields?mesh=1")).body.len();
    let part = get(a, &format!("/jobs/{id}/fields?mesh=1&surface=1"))
        .body
        .len();
    assert!(part < whole / 2, "{part} of {whole} bytes");

    // A bad flag is a 400 naming the parameter.
    for path in [
        format!("/jobs/{id}/fields?surface=yes"),
        format!("/jobs/{id}/mesh?surface=2"),
    ] {
        let p = assert_problem(&get(a, &path), 400);
        assert!(p["detail"].as_str().unwrap().contains("surface"), "{p}");
    }
    srv.stop();
    let _ = std::fs::remove_dir_all(&dir);
}

/// The picture of a plane body is all of it: `surface=1` changes nothing in 2D.
#[test]
fn a_2d_jobs_fields_and_mesh_are_whole_with_surface() {
    let dir = temp_dir("2d");
    let srv = Server::start_with(Config {
        data_dir: dir.clone(),
        workers: 1,
        max_nodes: 20_000,
        ..Config::default()
    });
    let a = srv.addr;
    let id = submit(a, "paper-exp2", "1/4");
    let with = get(a, &format!("/jobs/{id}/fields?mesh=1&surface=1")).json();
    let without = get(a, &format!("/jobs/{id}/fields?mesh=1")).json();
    assert_eq!(with, without);
    assert_eq!(with["mesh"]["dim"], 2);
    assert!(with["mesh"].get("surface").is_none());
    assert_eq!(
        get(a, &format!("/jobs/{id}/mesh?surface=1")).json(),
        get(a, &format!("/jobs/{id}/mesh")).json()
    );
    srv.stop();
    let _ = std::fs::remove_dir_all(&dir);
}
