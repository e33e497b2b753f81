//! `POST /jobs {"continue": {...}}` over real HTTP: a finished simulation continued to a later
//! final time gives the steps of one run to that time (bit for bit on the direct path, to
//! 1e-12 on the multigrid path; 2D and 3D, slipping), numbered from the parent's start and
//! linked to it; the same continuation twice is one job; a changed scene on the same mesh
//! and body is accepted; every refusal is a 422 at its member of `/continue`.

use contact_sim::Config;
use serde_json::{json, Value};
use std::path::PathBuf;
use std::time::Duration;

mod common;
use common::http::{assert_problem, get, post_json, wait_status};
use common::server::Server;

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("contact-sim-continue-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// `preset` at h = k = 1/`level` to t = `steps`/`level`, on the `linear` path, with a
/// Tresca bound low enough to make Γ3 slip, storing every step.
fn scene(preset: &str, level: usize, steps: usize, linear: &str) -> Value {
    let mut s = contact_core::scene::presets::get(preset).unwrap();
    s["mesh"]["h"] = json!(format!("1/{level}"));
    s["time"] = json!({"t_end": format!("{steps}/{level}"), "k": format!("1/{level}")});
    s["solver"] = json!({"linear": linear});
    s["friction"] = json!({"law": "tresca", "g": 0.05});
    s["output"] = json!({"every": 1, "fields": ["u", "zeta"]});
    s
}

fn submit(a: std::net::SocketAddr, body: &Value, status: u16) -> String {
    let r = post_json(a, "/jobs", body);
    assert_eq!(r.status, status, "{}", r.text());
    let id = r.json()["id"].as_str().unwrap().to_string();
    wait_status(a, &id, &["succeeded"], Duration::from_secs(120));
    id
}

/// The per-step figures of a summary: (n, t, w_V, u_V, ζ_L2, ζ_min, slipping nodes).
fn steps(summary: &Value) -> Vec<(u64, [f64; 5], u64)> {
    summary["steps"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| {
            let f = |k: &str| s[k].as_f64().unwrap();
            (
                s["n"].as_u64().unwrap(),
                [f("t"), f("w_V"), f("u_V"), f("zeta_L2"), f("zeta_min")],
                s["slip_nodes"].as_u64().unwrap(),
            )
        })
        .collect()
}

fn numbers(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

/// Largest relative difference of two equally long lists (relative to the larger entry of
/// the first, or 1).
fn rel_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    let scale = a.iter().fold(1e-300_f64, |m, x| m.max(x.abs()));
    a.iter()
        .zip(b)
        .fold(0.0, |m, (x, y)| m.max((x - y).abs() / scale))
}

/// Runs `preset` to `first` steps, continues it to `total`, runs it straight to `total`,
/// and compares: bit for bit when `tol` is 0, else to `tol` relative.
fn continued_equals_one_run(
    a: std::net::SocketAddr,
    preset: &str,
    level: usize,
    (first, total): (usize, usize),
    linear: &str,
    tol: f64,
) {
    let case = format!("{preset}, {linear}");
    let parent = submit(a, &scene(preset, level, first, linear), 202);
    let t_end = format!("{total}/{level}");
    let request = json!({"continue": {"job": parent, "t_end": t_end}});
    let child = submit(a, &request, 202);
    let long = submit(a, &scene(preset, level, total, linear), 202);

    let view = get(a, &format!("/jobs/{child}")).json();
    assert_eq!(view["continued_from"]["job"], parent, "{case}: {view}");
    assert_eq!(view["continued_from"]["step"], first, "{case}");
    assert_eq!(view["links"]["parent"], format!("/jobs/{parent}"));
    assert_eq!(view["progress"]["steps"], total, "{case}");

    let cs = get(a, &format!("/jobs/{child}/summary")).json();
    let ls = get(a, &format!("/jobs/{long}/summary")).json();
    assert_eq!(
        cs["continued_from"]["job"], parent,
        "{case}: the summary links the parent"
    );
    assert_eq!(cs["continued_from"]["step"], first);
    let (cst, lst) = (steps(&cs), steps(&ls));
    assert_eq!(
        cst.len(),
        total,
        "{case}: steps numbered from the parent's start"
    );
    assert_eq!(
        cst.iter().map(|s| s.0).collect::<Vec<_>>(),
        (1..=total as u64).collect::<Vec<_>>()
    );
    assert!(
        lst.iter().any(|s| s.2 > 0),
        "{case}: Γ3 slips in this scene"
    );
    for (c, l) in cst.iter().zip(&lst) {
        assert_eq!((c.0, c.2), (l.0, l.2), "{case}: step {}", c.0);
        if tol == 0.0 {
            let bits = |v: &[f64; 5]| v.map(f64::to_bits);
            assert_eq!(bits(&c.1), bits(&l.1), "{case}: step {} bit for bit", c.0);
        } else {
            let d = rel_diff(&l.1, &c.1);
            assert!(d <= tol, "{case}: step {}: relative difference {d:e}", c.0);
        }
    }
    // The child stores the steps after the parent's, numbered from the parent's start.
    assert_eq!(
        get(a, &format!("/jobs/{child}/fields?step={first}")).status,
        404,
        "{case}: the parent's steps are the parent's"
    );
    for n in first + 1..=total {
        let cf = get(a, &format!("/jobs/{child}/fields?step={n}")).json();
        let lf = get(a, &format!("/jobs/{long}/fields?step={n}")).json();
        assert_eq!(cf["n"], n);
        assert_eq!(cf["t"], lf["t"], "{case}: step {n}'s time");
        for field in ["u", "zeta"] {
            let (c, l) = (numbers(&cf[field]), numbers(&lf[field]));
            if tol == 0.0 {
                assert_eq!(c, l, "{case}: {field} at step {n}");
            } else {
                let d = rel_diff(&l, &c);
                assert!(d <= tol, "{case}: {field} at step {n}: {d:e}");
            }
        }
    }
    // The same continuation again is the same computation: 200 with the first job.
    let again = post_json(a, "/jobs", &request);
    assert_eq!(again.status, 200, "{}", again.text());
    assert_eq!(again.json()["id"], child.as_str());
    // And a continuation can itself be continued.
    let grand = json!({"continue": {"job": child, "t_end": format!("{}/{level}", total + 1)}});
    let g = submit(a, &grand, 202);
    let gs = get(a, &format!("/jobs/{g}/summary")).json();
    assert_eq!(steps(&gs).len(), total + 1);
    assert_eq!(gs["continued_from"]["job"], child.as_str());
}

#[test]
fn a_continued_job_equals_one_long_job() {
    let dir = temp_dir("equal");
    let srv = Server::start_with(Config {
        data_dir: dir.clone(),
        workers: 2,
        ..Config::default()
    });
    let a = srv.addr;
    continued_equals_one_run(a, "paper-convergence", 8, (2, 4), "direct", 0.0);
    continued_equals_one_run(a, "paper-convergence", 8, (2, 4), "multigrid", 1e-12);
    continued_equals_one_run(a, "box-exp3", 4, (1, 2), "direct", 0.0);
    continued_equals_one_run(a, "box-exp3", 4, (1, 2), "multigrid", 1e-12);
    srv.stop();
    std::fs::remove_dir_all(&dir).ok();
}

/// The 422 of a refused continuation names `pointer`.
fn refused(a: std::net::SocketAddr, body: &Value, pointer: &str) -> String {
    let p = assert_problem(&post_json(a, "/jobs", body), 422);
    assert_eq!(p["errors"][0]["pointer"], pointer, "{body}: {p}");
    p["errors"][0]["message"].as_str().unwrap().to_string()
}

#[test]
fn continuations_are_refused_at_their_member() {
    let dir = temp_dir("refused");
    let srv = Server::start_with(Config {
        data_dir: dir.clone(),
        workers: 1,
        ..Config::default()
    });
    let a = srv.addr;
    let parent_scene = scene("paper-convergence", 4, 2, "direct");
    let parent = submit(a, &parent_scene, 202);

    let unknown = uuid::Uuid::new_v4().to_string();
    let m = refused(
        a,
        &json!({"continue": {"job": unknown, "t_end": 1}}),
        "/continue/job",
    );
    assert!(m.contains("no job"), "{m}");
    refused(
        a,
        &json!({"continue": {"job": "nope", "t_end": 1}}),
        "/continue/job",
    );
    refused(a, &json!({"continue": {"t_end": 1}}), "/continue/job");
    refused(a, &json!({"continue": {"job": parent}}), "/continue/t_end");
    // Not after the parent's final time 1/2; not a whole number of its steps 1/4.
    let m = refused(
        a,
        &json!({"continue": {"job": parent, "t_end": "1/2"}}),
        "/continue/t_end",
    );
    assert!(m.contains("after the parent's final time"), "{m}");
    refused(
        a,
        &json!({"continue": {"job": parent, "t_end": 0.6}}),
        "/continue/t_end",
    );
    refused(
        a,
        &json!({"continue": {"job": parent, "t_end": 1, "steps": 3}}),
        "/continue/steps",
    );
    refused(
        a,
        &json!({"continue": {"job": parent, "t_end": 1}, "name": "x"}),
        "/name",
    );
    // A changed scene must keep the mesh and the body, and the parent's k.
    let mut other_mesh = parent_scene.clone();
    other_mesh["mesh"]["h"] = json!("1/8");
    refused(
        a,
        &json!({"continue": {"job": parent, "t_end": 1, "scene": other_mesh}}),
        "/continue/scene/mesh",
    );
    let mut other_body = parent_scene.clone();
    other_body["material"]["viscosity"] = json!(1);
    let mut other_k = parent_scene.clone();
    other_k["time"] = json!({"t_end": 1, "k": "1/8"});
    refused(
        a,
        &json!({"continue": {"job": parent, "scene": other_k}}),
        "/continue/scene/time/k",
    );
    let mut bad_friction = parent_scene.clone();
    bad_friction["friction"]["g"] = json!(-1);
    bad_friction.as_object_mut().unwrap().remove("time");
    // The parent's scene as it is, k included, with a final time of its own is fine; two
    // final times are one too many.
    let mut both = parent_scene.clone();
    both["time"]["t_end"] = json!(2);
    refused(
        a,
        &json!({"continue": {"job": parent, "t_end": 1, "scene": both}}),
        "/continue/scene/time/t_end",
    );
    refused(
        a,
        &json!({"continue": {"job": parent, "t_end": 1, "scene": bad_friction}}),
        "/continue/scene/friction/g",
    );
    // A running (or queued) job has not stored its last state.
    let mut long = scene("paper-convergence", 16, 1, "direct");
    long["time"] = json!({"t_end": 1, "N": 50_000});
    long["output"] = json!({"every": 50_000, "fields": ["u"]});
    let r = post_json(a, "/jobs", &long);
    assert_eq!(r.status, 202);
    let running = r.json()["id"].as_str().unwrap().to_string();
    let m = refused(
        a,
        &json!({"continue": {"job": running, "t_end": 2}}),
        "/continue/job",
    );
    assert!(m.contains("queued") || m.contains("running"), "{m}");
    common::http::http(a, "POST", &format!("/jobs/{running}/cancel"), &[], b"");
    wait_status(a, &running, &["cancelled"], Duration::from_secs(30));
    refused(
        a,
        &json!({"continue": {"job": running, "t_end": 2}}),
        "/continue/job",
    );

    // Another friction and a later time: accepted, and the child's friction is its own.
    let mut slower = parent_scene.clone();
    slower["friction"]["g"] = json!(0.5);
    slower["time"]["t_end"] = json!(1);
    let child = submit(
        a,
        &json!({"continue": {"job": parent, "scene": slower}}),
        202,
    );
    let cs = get(a, &format!("/jobs/{child}/summary")).json();
    assert_eq!(steps(&cs).len(), 4);
    assert_eq!(cs["time"]["t_end"], 1.0);
    // A viscosity changed is a changed body.
    refused(
        a,
        &json!({"continue": {"job": parent, "t_end": 1, "scene": other_body}}),
        "/continue/scene/material",
    );
    srv.stop();
    std::fs::remove_dir_all(&dir).ok();
}
