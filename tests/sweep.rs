//! Parameter sweeps over real HTTP. Every member is a job of its own: a 3 × 2 sweep gives
//! the rows of six single jobs (bit for bit), takes the members already computed as jobs
//! from them and computes each other member once, as a job listed with a link to its sweep;
//! a single job submitted later for a member's scene is answered with the member's job and
//! computes nothing; its table as CSV and its plot as SVG; bad sweeps are 422 at
//! `/sweep/...`. Cancelling a sweep cancels the members it created (not a job it took from
//! earlier); a cancelled member fails its sweep, naming it; another owner's job submitted
//! after a sweep runs before the sweep's last member (fair share, one worker). (A server
//! killed while members run completes the sweep after its restart: `tests/crash.rs`.)

use contact_sim::Config;
use serde_json::{json, Value};
use std::path::PathBuf;
use std::time::Duration;

mod common;
use common::http::{assert_problem, get, http, post_json, wait_status};
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
    assert_eq!(
        view["progress"]["step"], view["progress"]["steps"],
        "{view}"
    );
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
    // The sweep lists its members' jobs in member order, as its summary's rows name them.
    let members: Vec<Value> = rows.iter().map(|r| r["job"].clone()).collect();
    assert_eq!(view["members"], json!(members));
    // Every member is a job listed beside the sweep: the two taken, four created.
    let listed = get(a, "/jobs?limit=500").json();
    let listed: Vec<&str> = listed["jobs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|j| j["id"].as_str().unwrap())
        .collect();
    assert_eq!(listed.len(), 2 + 4 + 1, "{listed:?}");
    let steps_after_sweep = steps_computed(a);
    for (i, row) in rows.iter().enumerate() {
        let (g, kappa) = (&gs[i / 2], &kappas[i % 2]);
        assert_eq!(row["values"]["/friction/g"], *g, "row {i}");
        assert_eq!(row["values"]["/damage/kappa"], *kappa, "row {i}");
        assert_eq!(row["cached"], i == 0 || i == 5, "row {i}");
        let member = row["job"].as_str().unwrap();
        assert!(listed.contains(&member), "row {i}: {member}");
        let job = get(a, &format!("/jobs/{member}")).json();
        assert_eq!(job["kind"], "simulation", "row {i}");
        assert_eq!(job["status"], "succeeded", "row {i}");
        // A member this sweep created links to it; one taken from a job is that job.
        if i == 0 || i == 5 {
            assert!(job["links"].get("sweep").is_none(), "row {i}: {job}");
        } else {
            assert_eq!(job["links"]["sweep"], format!("/jobs/{sweep}"), "row {i}");
            assert_eq!(job["sweep"], sweep.as_str(), "row {i}");
        }
        // The same computation as a single job: answered by the member's job (200), never
        // computed again; the figures are the same bits.
        let (status, id) = run(a, &single(g, kappa));
        assert_eq!(status, 200, "row {i}");
        assert_eq!(id, member, "row {i}");
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
    assert_eq!(
        steps_computed(a),
        steps_after_sweep,
        "the single jobs of the members computed steps"
    );
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

/// The paper-convergence scene at h = 1/16 with `n` steps to t = 1 (only the last stored):
/// a member that runs long enough to be caught running.
fn long_scene(n: u32) -> Value {
    let mut s = scene();
    s["mesh"]["h"] = json!("1/16");
    s["time"] = json!({"t_end": 1, "N": n});
    s["output"] = json!({"every": n, "fields": ["u"]});
    s
}

/// Waits until `pred` holds for the job's view.
fn wait_for(a: std::net::SocketAddr, id: &str, what: &str, pred: impl Fn(&Value) -> bool) -> Value {
    let t = std::time::Instant::now();
    loop {
        let j = get(a, &format!("/jobs/{id}")).json();
        if pred(&j) {
            return j;
        }
        assert!(t.elapsed() < Duration::from_secs(120), "{what}: {j}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Cancelling a sweep cancels the members it created, the running one within a step; the
/// member taken from the user's own earlier job stays that job, succeeded. The sweep's
/// progress is its members'.
#[test]
fn a_sweep_is_cancelled_with_its_members() {
    let dir = temp_dir("cancel");
    let srv = Server::start_with(Config {
        data_dir: dir.clone(),
        workers: 1,
        ..Config::default()
    });
    let a = srv.addr;
    // Member 0 (8 steps) is computed before as the user's own job.
    let mut first = long_scene(20_000);
    first["time"]["N"] = json!(8);
    first["friction"]["g"] = json!(0.5);
    let (_, own) = run(a, &first);
    let r = post_json(
        a,
        "/jobs",
        &json!({"sweep": {"scene": long_scene(20_000), "mode": "zip",
                          "vary": {"/friction/g": [0.5, 1, 2], "/time/N": [8, 20_000, 20_000]}}}),
    );
    assert_eq!(r.status, 202, "{}", r.text());
    let id = r.json()["id"].as_str().unwrap().to_string();
    assert_eq!(
        r.json()["progress"]["steps"],
        8 + 2 * 20_000,
        "the steps of all members"
    );
    // The sweep's progress moves with its running member's steps (past the 8 taken).
    let view = wait_for(a, &id, "the sweep's progress", |j| {
        j["progress"]["step"].as_u64().unwrap_or(0) > 8
    });
    let members: Vec<String> = view["members"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m.as_str().unwrap().to_string())
        .collect();
    assert_eq!(members.len(), 3, "{view}");
    assert_eq!(members[0], own);
    assert_eq!(
        view["status"], "queued",
        "a waiting sweep holds no worker: {view}"
    );
    let c = http(a, "POST", &format!("/jobs/{id}/cancel"), &[], b"");
    assert_eq!(c.status, 202, "{}", c.text());
    wait_status(a, &id, &["cancelled"], Duration::from_secs(10));
    for m in &members[1..] {
        let done = wait_status(a, m, &["cancelled"], Duration::from_secs(10));
        assert_eq!(done["links"]["sweep"], format!("/jobs/{id}"));
        assert!(
            done["progress"]["step"].as_u64().unwrap() < 20_000,
            "{done}"
        );
    }
    assert_eq!(
        get(a, &format!("/jobs/{own}")).json()["status"],
        "succeeded"
    );
    assert_problem(&get(a, &format!("/jobs/{id}/table.csv")), 409);
    srv.stop();
    std::fs::remove_dir_all(&dir).ok();
}

/// A member cancelled on its own fails its sweep with a problem naming the member, and the
/// sweep's other members are cancelled with it (two workers: the sweep is taken while its
/// other member still runs).
#[test]
fn a_failed_member_fails_its_sweep_naming_it() {
    let dir = temp_dir("member");
    let srv = Server::start_with(Config {
        data_dir: dir.clone(),
        workers: 2,
        ..Config::default()
    });
    let a = srv.addr;
    let r = post_json(
        a,
        "/jobs",
        &json!({"sweep": {"scene": long_scene(20_000), "vary": {"/friction/g": [1, 2]}}}),
    );
    assert_eq!(r.status, 202, "{}", r.text());
    let id = r.json()["id"].as_str().unwrap().to_string();
    let view = wait_for(a, &id, "members", |j| {
        j["members"].as_array().is_some_and(|m| m.len() == 2)
    });
    let second = view["members"][1].as_str().unwrap().to_string();
    let c = http(a, "POST", &format!("/jobs/{second}/cancel"), &[], b"");
    assert_eq!(c.status, 202, "{}", c.text());
    let done = wait_status(a, &id, &["failed"], Duration::from_secs(60));
    let error = &done["error"];
    assert_eq!(error["type"], "/problems/sweep-member", "{error}");
    assert_eq!(error["status"], 409, "a cancelled member: {error}");
    assert_eq!(
        error["errors"][0]["pointer"], "/sweep/vary/~1friction~1g",
        "{error}"
    );
    let detail = error["detail"].as_str().unwrap();
    assert!(detail.contains("member 1 (/friction/g = 2)"), "{detail}");
    assert!(detail.contains(&second), "{detail}");
    let first = view["members"][0].as_str().unwrap();
    wait_status(a, first, &["cancelled"], Duration::from_secs(10));
    srv.stop();
    std::fs::remove_dir_all(&dir).ok();
}

/// Fair share: with one worker, another owner's job submitted after a sweep of four members
/// started runs before the sweep's last member (claims alternate between owners).
#[test]
fn another_owners_job_is_not_starved_by_a_sweep() {
    use contact_sim::auth::keys::{new_token, token_hash};
    use contact_sim::store::owners::{Owners, Quotas};
    let dir = temp_dir("fair");
    let tokens: Vec<String> = ["alice", "bob"]
        .iter()
        .map(|name| {
            let store =
                contact_sim::store::sqlite::SqliteStore::open(&dir.join("jobs.sqlite3")).unwrap();
            let token = new_token().unwrap();
            store
                .add_key(name, &token_hash(&token), false, Quotas::default())
                .unwrap();
            token
        })
        .collect();
    let srv = Server::start_with(Config {
        data_dir: dir.clone(),
        workers: 1,
        auth: contact_sim::auth::AuthMode::Required,
        ..Config::default()
    });
    let a = srv.addr;
    let auth = |t: &str| format!("Bearer {t}");
    let post = |token: &str, body: &Value| {
        let r = http(
            a,
            "POST",
            "/jobs",
            &[
                ("authorization", &auth(token)),
                ("content-type", "application/json"),
            ],
            body.to_string().as_bytes(),
        );
        assert_eq!(r.status, 202, "{}", r.text());
        r.json()["id"].as_str().unwrap().to_string()
    };
    let view = |token: &str, id: &str| {
        http(
            a,
            "GET",
            &format!("/jobs/{id}"),
            &[("authorization", &auth(token))],
            b"",
        )
        .json()
    };
    let sweep = post(
        &tokens[0],
        &json!({"sweep": {"scene": long_scene(400), "vary": {"/friction/g": [0.5, 1, 2, 4]}}}),
    );
    let t = std::time::Instant::now();
    let members = loop {
        let v = view(&tokens[0], &sweep);
        if let Some(m) = v["members"].as_array().filter(|m| m.len() == 4) {
            break m.clone();
        }
        assert!(t.elapsed() < Duration::from_secs(60), "{v}");
        std::thread::sleep(Duration::from_millis(10));
    };
    let plain = post(&tokens[1], &long_scene(40));
    let t = std::time::Instant::now();
    loop {
        let v = view(&tokens[1], &plain);
        if v["status"] == "succeeded" {
            break;
        }
        assert!(t.elapsed() < Duration::from_secs(120), "{v}");
        std::thread::sleep(Duration::from_millis(10));
    }
    let waiting = members
        .iter()
        .filter(|m| view(&tokens[0], m.as_str().unwrap())["status"] == "queued")
        .count();
    assert!(waiting >= 1, "the plain job ran after every member");
    let done = {
        let t = std::time::Instant::now();
        loop {
            let v = view(&tokens[0], &sweep);
            if v["status"] == "succeeded" || v["status"] == "failed" {
                break v;
            }
            assert!(t.elapsed() < Duration::from_secs(120), "{v}");
            std::thread::sleep(Duration::from_millis(20));
        }
    };
    assert_eq!(done["status"], "succeeded", "{done}");
    srv.stop();
    std::fs::remove_dir_all(&dir).ok();
}
