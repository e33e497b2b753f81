//! Parameter sweeps over real HTTP: a 3 × 2 sweep gives the rows of six single jobs (bit for
//! bit), takes the members already computed as jobs from them and computes each other member
//! once; its table as CSV and its plot as SVG; bad sweeps are 422 at `/sweep/...`.

use contact_sim::Config;
use serde_json::{json, Value};
use std::path::PathBuf;
use std::time::Duration;

mod common;
use common::http::{assert_problem, get, post_json, wait_status};
use common::server::Server;

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("contact-sim-sweep-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// paper-convergence at h = k = 1/8 to t = 1/2, Tresca friction (g = 0.05 makes Γ3 slip).
fn scene() -> Value {
    let mut s = contact_core::scene::presets::get("paper-convergence").unwrap();
    s["mesh"]["h"] = json!("1/8");
    s["time"] = json!({"t_end": "1/2", "k": "1/8"});
    s["friction"] = json!({"law": "tresca", "g": 1});
    s["solver"] = json!({"linear": "direct"});
    s["output"] = json!({"every": 4, "fields": ["u"]});
    s
}

fn run(a: std::net::SocketAddr, body: &Value) -> (u16, String) {
    let r = post_json(a, "/jobs", body);
    assert!(r.status == 202 || r.status == 200, "{}", r.text());
    let id = r.json()["id"].as_str().unwrap().to_string();
    let done = wait_status(a, &id, &["succeeded", "failed"], Duration::from_secs(120));
    assert_eq!(done["status"], "succeeded", "{done}");
    (r.status, id)
}

/// Time steps computed by the node so far (its metrics).
fn steps_computed(a: std::net::SocketAddr) -> u64 {
    let text = get(a, "/metrics").text();
    text.lines()
        .find(|l| l.starts_with("contact_sim_steps_total"))
        .and_then(|l| l.split_whitespace().last())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no step counter in the metrics:\n{text}"))
}

#[test]
fn a_sweep_equals_its_single_jobs_and_computes_each_member_once() {
    let dir = temp_dir("equal");
    let srv = Server::start_with(Config {
        data_dir: dir.clone(),
        workers: 1,
        ..Config::default()
    });
    let a = srv.addr;
    let gs = [json!(0.05), json!(1), json!(2)];
    let kappas = [json!(0.1), json!(0.5)];
    let single = |g: &Value, kappa: &Value| {
        let mut s = scene();
        s["friction"]["g"] = g.clone();
        s["damage"]["kappa"] = kappa.clone();
        s
    };
    // Two members are computed as single jobs before the sweep.
    let (_, before) = run(a, &single(&gs[0], &kappas[0]));
    run(a, &single(&gs[2], &kappas[1]));
    let steps_before = steps_computed(a);
    let body = json!({"sweep": {
        "name": "g and kappa",
        "scene": scene(),
        "vary": {"/friction/g": gs, "/damage/kappa": kappas},
    }});
    let (status, sweep) = run(a, &body);
    assert_eq!(status, 202);
    // Four members computed, 4 steps each; the other two were taken from the jobs.
    assert_eq!(steps_computed(a) - steps_before, 4 * 4);
    let view = get(a, &format!("/jobs/{sweep}")).json();
    assert_eq!(view["kind"], "study");
    assert_eq!(view["scene"], "g and kappa");
    assert_eq!(
        view["links"]["table_csv"],
        format!("/jobs/{sweep}/table.csv")
    );
    let summary = get(a, &format!("/jobs/{sweep}/summary")).json();
    assert_eq!(summary["kind"], "sweep");
    assert_eq!(summary["computed"], 4);
    let rows = summary["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 6);
    assert!(rows.iter().any(|r| r["slip_nodes"].as_u64().unwrap() > 0));
    for (i, row) in rows.iter().enumerate() {
        let (g, kappa) = (&gs[i / 2], &kappas[i % 2]);
        assert_eq!(row["values"]["/friction/g"], *g, "row {i}");
        assert_eq!(row["values"]["/damage/kappa"], *kappa, "row {i}");
        assert_eq!(row["cached"], i == 0 || i == 5, "row {i}");
        // The same computation as a single job: answered by the job the sweep took it
        // from (200) or computed now (202); the figures are the same bits.
        let (status, id) = run(a, &single(g, kappa));
        assert_eq!(status, if i == 0 || i == 5 { 200 } else { 202 }, "row {i}");
        if i == 0 {
            assert_eq!(id, before);
        }
        let s = get(a, &format!("/jobs/{id}/summary")).json();
        for (key, fin) in [
            ("w_V", "w_V"),
            ("u_V", "u_V"),
            ("zeta_L2", "zeta_L2"),
            ("zeta_min", "zeta_min"),
        ] {
            assert_eq!(
                row[key].as_f64().unwrap().to_bits(),
                s["final"][fin].as_f64().unwrap().to_bits(),
                "row {i}: {key}"
            );
        }
        let last = s["steps"].as_array().unwrap().last().unwrap();
        assert_eq!(row["slip_nodes"], last["slip_nodes"], "row {i}");
    }
    // The same sweep again is the same computation.
    let again = post_json(a, "/jobs", &body);
    assert_eq!(again.status, 200);
    assert_eq!(again.json()["id"], sweep.as_str());

    let csv = get(a, &format!("/jobs/{sweep}/table.csv"));
    assert_eq!(csv.status, 200);
    assert_eq!(csv.header("content-type"), Some("text/csv; charset=utf-8"));
    let text = csv.text();
    assert!(text.starts_with("member,/friction/g,/damage/kappa,w_V,u_V,zeta_L2,zeta_min,min_zeta,slip_nodes,max_slip_speed,steps,wall_s,cached\n"), "{text}");
    assert_eq!(text.lines().count(), 7);
    let plot = get(
        a,
        &format!("/jobs/{sweep}/plot.svg?quantity=max_slip_speed&against=/damage/kappa"),
    );
    assert_eq!(plot.status, 200);
    let svg = plot.text();
    assert_eq!(
        svg.matches("<g class=\"line\">").count(),
        3,
        "one line per g"
    );
    assert_problem(
        &get(a, &format!("/jobs/{sweep}/plot.svg?quantity=nope")),
        400,
    );
    assert_problem(
        &get(a, &format!("/jobs/{sweep}/plot.svg?against=/mesh/h")),
        400,
    );
    assert_problem(&get(a, &format!("/jobs/{before}/table.csv")), 404);
    assert_eq!(get(a, &format!("/jobs/{sweep}/report.svg")).status, 200);
    srv.stop();
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bad_sweeps_are_refused_at_their_member() {
    let dir = temp_dir("refused");
    let srv = Server::start_with(Config {
        data_dir: dir.clone(),
        workers: 1,
        max_nodes: 200,
        ..Config::default()
    });
    let a = srv.addr;
    let refused = |sweep: Value, pointer: &str| {
        let p = assert_problem(&post_json(a, "/jobs", &json!({ "sweep": sweep })), 422);
        assert_eq!(p["errors"][0]["pointer"], pointer, "{p}");
        p
    };
    refused(
        json!({"scene": scene(), "vary": {"/friction/g": [1, -1]}}),
        "/sweep/vary/~1friction~1g",
    );
    refused(
        json!({"scene": scene(), "vary": {"/nowhere/x": [1]}}),
        "/sweep/vary/~1nowhere~1x",
    );
    refused(
        json!({"scene": scene(), "vary": {"/friction/g": [1, 2], "/damage/kappa": [0.1]}, "mode": "zip"}),
        "/sweep/vary/~1damage~1kappa",
    );
    // The largest member decides: h = 1/16 has 289 nodes, over this node's 200.
    let p = refused(
        json!({"scene": scene(), "vary": {"/mesh/h": ["1/8", "1/16"]}}),
        "/sweep/vary/~1mesh~1h",
    );
    assert_eq!(p["limit"]["name"], "nodes", "{p}");
    refused(
        json!({"scene": scene(), "vary": {"/domain/mesh": ["plate-with-hole.msh"]}}),
        "/sweep/vary/~1domain~1mesh",
    );
    let many: Vec<u32> = (1..=65).collect();
    refused(
        json!({"scene": scene(), "vary": {"/friction/g": many}}),
        "/sweep/vary",
    );
    let p = assert_problem(
        &post_json(
            a,
            "/jobs",
            &json!({"sweep": {"scene": scene(), "vary": {"/friction/g": [1]}}, "x": 1}),
        ),
        422,
    );
    assert_eq!(p["errors"][0]["pointer"], "/x");
    srv.stop();
    std::fs::remove_dir_all(&dir).ok();
}

/// A cancel stops a running sweep within a step of its member.
#[test]
fn a_sweep_is_cancelled_with_its_members() {
    let dir = temp_dir("cancel");
    let srv = Server::start_with(Config {
        data_dir: dir.clone(),
        workers: 1,
        ..Config::default()
    });
    let a = srv.addr;
    let mut long = scene();
    long["mesh"]["h"] = json!("1/16");
    long["time"] = json!({"t_end": 1, "N": 20_000});
    long["output"] = json!({"every": 20_000, "fields": ["u"]});
    let r = post_json(
        a,
        "/jobs",
        &json!({"sweep": {"scene": long, "vary": {"/friction/g": [0.5, 1, 2]}}}),
    );
    assert_eq!(r.status, 202, "{}", r.text());
    let id = r.json()["id"].as_str().unwrap().to_string();
    assert_eq!(
        r.json()["progress"]["steps"],
        60_000,
        "the steps of all members"
    );
    let t = std::time::Instant::now();
    loop {
        let j = get(a, &format!("/jobs/{id}")).json();
        if j["status"] == "running" && j["progress"]["step"].as_u64().unwrap_or(0) > 0 {
            break;
        }
        assert!(t.elapsed() < Duration::from_secs(60), "{j}");
        std::thread::sleep(Duration::from_millis(20));
    }
    let c = common::http::http(a, "POST", &format!("/jobs/{id}/cancel"), &[], b"");
    assert_eq!(c.status, 202);
    let done = wait_status(a, &id, &["cancelled"], Duration::from_secs(10));
    assert!(
        done["progress"]["step"].as_u64().unwrap() < 20_000,
        "{done}"
    );
    assert_problem(&get(a, &format!("/jobs/{id}/table.csv")), 409);
    srv.stop();
    std::fs::remove_dir_all(&dir).ok();
}
