//! The job service over real HTTP on an ephemeral port: the whole lifecycle (submit, SSE,
//! summary, fields JSON, VTU, PVD, archive, metrics, delete), errors as problem+json,
//! idempotency, cancellation, and restart on the same data directory with resumption from a
//! checkpoint.

use contact_sim::Config;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::time::Duration;

mod common;
use common::http::{assert_problem, get, http, post_json, raw_request, wait_status};
use common::server::Server;

impl Server {
    fn start(data_dir: &Path, workers: usize) -> Server {
        Server::start_with(Config {
            data_dir: data_dir.to_path_buf(),
            workers,
            max_nodes: 20_000,
            ..Config::default()
        })
    }
}

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("contact-sim-api-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// A scene that takes a while: paper-convergence at h = 1/16 with many small steps.
fn long_scene(steps: usize) -> Value {
    let mut s: Value = serde_json::from_str(
        &serde_json::to_string(&contact_core::scene::presets::get("paper-convergence").unwrap())
            .unwrap(),
    )
    .unwrap();
    s["mesh"]["h"] = json!("1/16");
    s["time"] = json!({"t_end": 1, "N": steps});
    s["output"]["every"] = json!(steps / 4);
    s
}

#[test]
fn whole_lifecycle_over_http() {
    let dir = temp_dir("life");
    let srv = Server::start(&dir, 2);
    let a = srv.addr;
    assert_eq!(get(a, "/healthz").status, 200);
    assert!(
        String::from_utf8_lossy(&get(a, "/openapi.yaml").body).contains("/jobs/{id}/result.pvd")
    );
    // GET /docs: the contract rendered by the vendored Swagger UI, every file from this
    // server (no CDN), its licence beside it; the client's header links it.
    let docs = get(a, "/docs");
    assert_eq!(docs.status, 200);
    assert!(docs
        .header("content-type")
        .unwrap()
        .starts_with("text/html"));
    let page = docs.text();
    assert!(
        !page.contains("://"),
        "the reference page loads nothing from elsewhere"
    );
    for (file, needle) in [
        ("/client/docs.js", "/openapi.yaml"),
        (
            "/client/vendor/swagger-ui/swagger-ui-bundle.js",
            "SwaggerUIBundle",
        ),
        ("/client/vendor/swagger-ui/swagger-ui.css", ".swagger-ui"),
        ("/client/vendor/swagger-ui/LICENSE", "Apache License"),
        ("/client/vendor/swagger-ui/NOTICE", "swagger-ui"),
    ] {
        assert!(
            page.contains(file) || !file.ends_with(".js") && !file.ends_with(".css"),
            "{file}"
        );
        let r = get(a, file);
        assert_eq!(r.status, 200, "{file}");
        assert!(r.text().contains(needle), "{file} has {needle:?}");
    }
    assert!(get(a, "/").text().contains("href=\"/docs\""));
    assert_eq!(
        get(a, "/presets").json()["presets"]
            .as_array()
            .unwrap()
            .len(),
        contact_core::scene::presets::names().len()
    );

    let r = post_json(
        a,
        "/jobs",
        &json!({"preset": "paper-exp2", "overrides": {"h": "1/8", "k": "1/8"}}),
    );
    assert_eq!(r.status, 202, "{}", String::from_utf8_lossy(&r.body));
    let id = r.json()["id"].as_str().unwrap().to_string();
    assert_eq!(r.header("location"), Some(format!("/jobs/{id}").as_str()));

    // Follow the event stream to the end: it closes after the final status.
    let ev = String::from_utf8(get(a, &format!("/jobs/{id}/events")).body).unwrap();
    assert!(
        ev.contains("event: status") && ev.contains("\"succeeded\""),
        "{ev}"
    );

    let job = get(a, &format!("/jobs/{id}"));
    assert_eq!(job.json()["status"], "succeeded");
    // The overrides show in the resource: runs of one preset are told apart.
    assert_eq!(
        job.json()["resolution"],
        json!({"h": "1/8", "refine": null, "k": "1/8", "steps": 8, "t_end": 1})
    );
    assert!(job.header("retry-after").is_none());
    let etag = job.header("etag").unwrap().to_string();
    assert_eq!(
        http(
            a,
            "GET",
            &format!("/jobs/{id}"),
            &[("If-None-Match", &etag)],
            b""
        )
        .status,
        304
    );

    let summary = get(a, &format!("/jobs/{id}/summary")).json();
    assert_eq!(summary["time"]["steps"], 8);
    assert_eq!(summary["steps"].as_array().unwrap().len(), 8);
    assert!(summary["final"]["w_V"].as_f64().unwrap() > 0.0);
    let nodes = summary["mesh"]["nodes"].as_u64().unwrap() as usize;
    let triangles = summary["mesh"]["triangles"].as_u64().unwrap() as usize;

    for step in ["0", "3", "8", "last"] {
        let f = get(
            a,
            &format!("/jobs/{id}/fields?step={step}&fields=u,zeta,sigma"),
        );
        assert_eq!(f.status, 200, "{}", String::from_utf8_lossy(&f.body));
        let f = f.json();
        assert_eq!(f["u"].as_array().unwrap().len(), 2 * nodes);
        assert_eq!(f["zeta"].as_array().unwrap().len(), nodes);
        assert_eq!(f["sigma"].as_array().unwrap().len(), triangles);
        assert!(f.get("w").is_none(), "unrequested fields are left out");
    }
    // Step 0 is the initial state: the preset's u_0 = 0, w_0 = 0, ζ_0 = 1, σ_0 = B(ε(0), 1) =
    // 0, and no contact state (there is none before the first step), even when asked for.
    let f0 = get(a, &format!("/jobs/{id}/fields?step=0")).json();
    assert_eq!((f0["n"].as_u64(), f0["t"].as_f64()), (Some(0), Some(0.0)));
    for (name, value) in [("u", 0.0), ("w", 0.0), ("zeta", 1.0), ("von_mises", 0.0)] {
        let v = f0[name].as_array().unwrap();
        assert!(
            v.iter().all(|x| x.as_f64() == Some(value)),
            "{name} at t = 0"
        );
    }
    assert_eq!(f0["sigma"].as_array().unwrap().len(), triangles);
    assert!(f0.get("contact").is_none(), "no contact state at t = 0");
    let with_mesh = get(a, &format!("/jobs/{id}/fields?step=last&mesh=1")).json();
    assert_eq!(with_mesh["mesh"]["nodes"].as_array().unwrap().len(), nodes);
    // The boundary parts' kinds, in the scene's order, for colouring the boundary by kind.
    let parts: Vec<&str> = with_mesh["mesh"]["parts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["type"].as_str().unwrap())
        .collect();
    let exp2 = contact_core::scene::presets::get("paper-exp2").unwrap();
    let kinds: Vec<&str> = exp2["boundary"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| b["type"].as_str().unwrap())
        .collect();
    assert_eq!(parts, kinds);
    for e in with_mesh["mesh"]["boundary_edges"].as_array().unwrap() {
        assert!(e[1].is_null() || e[1].as_u64().unwrap() < parts.len() as u64);
    }
    assert_eq!(
        get(a, &format!("/jobs/{id}/mesh")).json()["parts"],
        with_mesh["mesh"]["parts"]
    );
    assert_problem(&get(a, &format!("/jobs/{id}/fields?step=99")), 404);
    assert_problem(&get(a, &format!("/jobs/{id}/fields?fields=pressure")), 400);

    // VTU: counts match the mesh, arrays have the right lengths.
    let vtu = String::from_utf8(get(a, &format!("/jobs/{id}/fields/8.vtu")).body).unwrap();
    assert!(
        vtu.contains(&format!("NumberOfPoints=\"{nodes}\""))
            && vtu.contains(&format!("NumberOfCells=\"{triangles}\""))
    );
    check_vtu_arrays(&vtu, nodes, triangles);
    // HEAD says the streamed VTU's length (the browser shows it beside the link), no body.
    let head = http(a, "HEAD", &format!("/jobs/{id}/fields/8.vtu"), &[], b"");
    assert_eq!(head.status, 200);
    assert_eq!(head.header("content-type"), Some("application/xml"));
    assert_eq!(
        head.header("content-length"),
        Some(vtu.len().to_string().as_str())
    );
    assert!(head.body.is_empty());
    assert_eq!(
        http(a, "HEAD", &format!("/jobs/{id}/fields/99.vtu"), &[], b"").status,
        404
    );
    // σ is the cells' symmetric tensor (xx, yy, zz, xy, yz, xz): the stored (xx, yy, xy) of
    // the fields JSON, bit for bit, and zeros.
    let xml = roxmltree::Document::parse(&vtu).expect("the VTU is well-formed XML");
    let sigma = vtu_f64s(&xml, "sigma");
    assert_eq!(sigma.len(), 6 * triangles);
    let stored = get(a, &format!("/jobs/{id}/fields?step=8&fields=sigma")).json();
    for (s6, s3) in sigma
        .chunks_exact(6)
        .zip(stored["sigma"].as_array().unwrap())
    {
        let s3: Vec<f64> = s3
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(s6, [s3[0], s3[1], 0.0, s3[2], 0.0, 0.0]);
    }
    assert!(sigma.iter().any(|&s| s != 0.0));
    // zlib is the default; ?compression=none is the same arrays raw, in a larger file.
    assert!(common::vtu::is_compressed(&vtu));
    let raw = get(a, &format!("/jobs/{id}/fields/8.vtu?compression=none"));
    assert_eq!(raw.status, 200);
    let raw = String::from_utf8(raw.body).unwrap();
    assert!(!common::vtu::is_compressed(&raw) && raw.len() > vtu.len());
    let raw_xml = roxmltree::Document::parse(&raw).expect("the raw VTU is well-formed XML");
    for name in ["Points", "connectivity", "u", "w", "zeta", "sigma", "types"] {
        assert_eq!(
            vtu_array(&xml, name).1,
            vtu_array(&raw_xml, name).1,
            "{name}"
        );
    }
    assert_problem(
        &get(a, &format!("/jobs/{id}/fields/8.vtu?compression=gzip")),
        400,
    );

    // PVD: step 0 (the initial state, t = 0) and the 8 stored steps, each a VTU that is there.
    let pvd = String::from_utf8(get(a, &format!("/jobs/{id}/result.pvd")).body).unwrap();
    let xml = roxmltree::Document::parse(&pvd).expect("the PVD is well-formed XML");
    let sets: Vec<(&str, &str)> = xml
        .descendants()
        .filter(|n| n.has_tag_name("DataSet"))
        .map(|n| {
            (
                n.attribute("timestep").unwrap(),
                n.attribute("file").unwrap(),
            )
        })
        .collect();
    assert_eq!(sets.len(), 9, "{pvd}");
    assert_eq!(sets[0].0, "0");
    for (n, (t, file)) in sets.iter().enumerate() {
        assert_eq!(t.parse::<f64>().unwrap(), n as f64 / 8.0);
        // Relative to the PVD's own URL, so a saved copy opens beside its files.
        assert_eq!(*file, format!("fields/{n}.vtu"));
    }
    let r0 = get(a, &format!("/jobs/{id}/{}", sets[0].1));
    assert_eq!(r0.status, 200);
    let vtu0 = String::from_utf8(r0.body).unwrap();
    check_vtu_arrays(&vtu0, nodes, triangles);
    let xml = roxmltree::Document::parse(&vtu0).expect("0.vtu is well-formed XML");
    assert_eq!(vtu_f64s(&xml, "TimeValue"), [0.0]);
    assert_eq!(vtu_array(&xml, "Step").1, 0u64.to_le_bytes());
    assert!(vtu_f64s(&xml, "u").iter().all(|&u| u == 0.0));
    assert!(vtu_f64s(&xml, "zeta").iter().all(|&z| z == 1.0));
    assert_eq!(vtu_f64s(&xml, "sigma"), vec![0.0; 6 * triangles]);
    // The contact arrays every other step has, with no state yet (w_0 = 0): all 0.
    assert_eq!(vtu_f64s(&xml, "slip_velocity"), vec![0.0; nodes]);
    assert_eq!(vtu_array(&xml, "contact_state").1, vec![0u8; nodes]);
    let tar = get(a, &format!("/jobs/{id}/archive.tar")).body;
    let names = tar_names(&tar);
    assert!(
        names.iter().all(|n| n.starts_with(&format!("{id}/"))),
        "{names:?}"
    );
    assert!(
        names.contains(&format!("{id}/summary.json"))
            && names.contains(&format!("{id}/result.pvd"))
            && names.contains(&format!("{id}/fields/step_000000.vtu"))
    );
    assert_eq!(names.iter().filter(|n| n.ends_with(".vtu")).count(), 9);
    // The archive opens in ParaView offline: its PVD names the VTU files by paths relative
    // to itself, each a member of the archive (the browser's "ParaView" link is the archive).
    let mut archive = tar::Archive::new(tar.as_slice());
    let mut member_pvd = String::new();
    let mut vtus = 0;
    for entry in archive.entries().unwrap() {
        let mut entry = entry.unwrap();
        let path = entry.path().unwrap().to_string_lossy().to_string();
        if path == format!("{id}/result.pvd") {
            std::io::Read::read_to_string(&mut entry, &mut member_pvd).unwrap();
        }
        // Each VTU member (streamed into the archive as it is rendered) is the step's file.
        if let Some(n) = path
            .strip_prefix(&format!("{id}/fields/step_"))
            .and_then(|r| r.strip_suffix(".vtu"))
        {
            let mut member = Vec::new();
            std::io::Read::read_to_end(&mut entry, &mut member).unwrap();
            let n: usize = n.parse().unwrap();
            assert!(
                member == get(a, &format!("/jobs/{id}/fields/{n}.vtu")).body,
                "archive member step {n}"
            );
            vtus += 1;
        }
    }
    assert_eq!(vtus, 9);
    // ?compression=none: the same archive with raw VTU files.
    let raw_tar = get(a, &format!("/jobs/{id}/archive.tar?compression=none")).body;
    let mut raw_archive = tar::Archive::new(raw_tar.as_slice());
    let last = raw_archive
        .entries()
        .unwrap()
        .map(|e| e.unwrap())
        .find(|e| e.path().unwrap().ends_with("fields/step_000008.vtu"));
    let mut member = String::new();
    std::io::Read::read_to_string(&mut last.expect("step 8 in the raw archive"), &mut member)
        .unwrap();
    assert_eq!(member, raw);
    let xml = roxmltree::Document::parse(&member_pvd).expect("the archive's PVD is XML");
    let files: Vec<&str> = xml
        .descendants()
        .filter(|n| n.has_tag_name("DataSet"))
        .map(|n| n.attribute("file").unwrap())
        .collect();
    assert_eq!(files.len(), 9, "{member_pvd}");
    for f in files {
        assert!(!f.starts_with('/') && !f.contains("://"), "{f} is relative");
        assert!(
            names.contains(&format!("{id}/{f}")),
            "{f} is in the archive"
        );
    }

    let metrics = String::from_utf8(get(a, "/metrics").body).unwrap();
    assert!(
        metrics.contains("contact_sim_jobs{status=\"succeeded\"} 1"),
        "{metrics}"
    );
    assert!(metrics.contains("contact_sim_steps_total 8"));

    // An identical request is answered from the store.
    let again = post_json(
        a,
        "/jobs",
        &json!({"preset": "paper-exp2", "overrides": {"h": "1/8", "k": "1/8"}}),
    );
    assert_eq!(again.status, 200);
    assert_eq!(again.json()["id"], id.as_str());
    // So is the same computation written out as a scene under another name: a name changes
    // no number, and the answer is the first job (with its name).
    let mut renamed = contact_core::scene::presets::get("paper-exp2").unwrap();
    contact_core::scene::apply_overrides(
        &mut renamed,
        &contact_core::scene::Overrides {
            h: Some(json!("1/8")),
            k: Some(json!("1/8")),
            t_end: None,
        },
    );
    renamed["name"] = json!("the same bracket under another name");
    renamed["$schema"] = json!("/scene.schema.json");
    let named = post_json(a, "/jobs", &renamed);
    assert_eq!(
        named.status,
        200,
        "{}",
        String::from_utf8_lossy(&named.body)
    );
    assert_eq!(named.json()["id"], id.as_str());
    assert_eq!(named.json()["scene"], "paper-exp2");
    // A changed number is another computation.
    renamed["damage"]["kappa"] = json!(0.25);
    let other = post_json(a, "/jobs", &renamed);
    assert_eq!(
        other.status,
        202,
        "{}",
        String::from_utf8_lossy(&other.body)
    );
    assert_ne!(other.json()["id"], id.as_str());
    let other_id = other.json()["id"].as_str().unwrap().to_string();
    wait_status(a, &other_id, &["succeeded"], Duration::from_secs(120));
    assert_eq!(
        http(a, "DELETE", &format!("/jobs/{other_id}"), &[], b"").status,
        204
    );

    let list = get(a, "/jobs?status=succeeded").json();
    assert_eq!(list["jobs"].as_array().unwrap().len(), 1);
    assert_eq!(
        http(a, "DELETE", &format!("/jobs/{id}"), &[], b"").status,
        204
    );
    assert_problem(&get(a, &format!("/jobs/{id}")), 404);
    srv.stop();
    std::fs::remove_dir_all(&dir).ok();
}

/// Decodes every DataArray (either encoding, its headers checked) and checks its length.
fn check_vtu_arrays(vtu: &str, nodes: usize, cells: usize) {
    let compressed = common::vtu::is_compressed(vtu);
    let mut seen = 0;
    for part in vtu.split("<DataArray").skip(1) {
        let (attrs, rest) = part.split_once('>').unwrap();
        let data = rest.split("</DataArray>").next().unwrap().trim();
        let attr = |k: &str| {
            attrs
                .split(&format!("{k}=\""))
                .nth(1)
                .map(|s| s.split('"').next().unwrap().to_string())
        };
        let name = attr("Name").unwrap_or_default();
        let comps: usize = attr("NumberOfComponents").map_or(1, |c| c.parse().unwrap());
        let width = match attr("type").unwrap().as_str() {
            "Float64" | "Int64" | "UInt64" => 8,
            "UInt8" => 1,
            t => panic!("type {t}"),
        };
        let count = common::vtu::decode(data, compressed).len() / width / comps;
        let expect = match name.as_str() {
            "Points" | "u" | "w" | "zeta" | "contact_state" | "slip_velocity" => nodes,
            "connectivity" => 3 * cells,
            "offsets" | "types" | "sigma" | "von_mises" => cells,
            "TimeValue" | "Step" => 1,
            n => panic!("unexpected array {n}"),
        };
        assert_eq!(count, expect, "{name}");
        seen += 1;
    }
    assert!(seen >= 8, "only {seen} arrays");
}

/// The `<DataArray Name="name">` of a VTU: its element (checked to be unique) and its
/// decoded payload (its headers checked).
fn vtu_array<'a>(xml: &'a roxmltree::Document, name: &str) -> (roxmltree::Node<'a, 'a>, Vec<u8>) {
    let found: Vec<_> = xml
        .descendants()
        .filter(|n| n.has_tag_name("DataArray") && n.attribute("Name") == Some(name))
        .collect();
    assert_eq!(found.len(), 1, "arrays named {name}");
    let text: String = found[0].children().filter_map(|c| c.text()).collect();
    let compressed = xml.root_element().attribute("compressor") == Some("vtkZLibDataCompressor");
    (found[0], common::vtu::decode(&text, compressed))
}

/// A Float64 array of a VTU; for `sigma`, also checks that it is the cells' symmetric tensor.
fn vtu_f64s(xml: &roxmltree::Document, name: &str) -> Vec<f64> {
    let (node, data) = vtu_array(xml, name);
    assert_eq!(node.attribute("type"), Some("Float64"));
    if name == "sigma" {
        assert_eq!(node.attribute("NumberOfComponents"), Some("6"));
        let names: Vec<_> = (0..6)
            .map(|i| {
                node.attribute(format!("ComponentName{i}").as_str())
                    .unwrap()
            })
            .collect();
        assert_eq!(names, ["xx", "yy", "zz", "xy", "yz", "xz"]);
        let cell_data = node.parent_element().unwrap();
        assert!(cell_data.has_tag_name("CellData"));
        assert_eq!(cell_data.attribute("Tensors"), Some("sigma"));
    }
    data.chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
        .collect()
}

fn tar_names(tar: &[u8]) -> Vec<String> {
    let mut names = Vec::new();
    let mut off = 0;
    while off + 512 <= tar.len() && tar[off] != 0 {
        let h = &tar[off..off + 512];
        let name = String::from_utf8_lossy(&h[..100])
            .trim_end_matches('\0')
            .to_string();
        let size = usize::from_str_radix(std::str::from_utf8(&h[124..135]).unwrap(), 8).unwrap();
        names.push(name);
        off += 512 + size.div_ceil(512) * 512;
    }
    names
}

/// The study presets (the paper's Tables 1 and 2) are listed apart from the scenes and served
/// at /presets/{name} as the body that POST /jobs runs; other names stay 404.
/// A scene that asks for the a posteriori estimate gets its parts per step and over the run in
/// the summary, the cell field in the fields JSON and every VTU (zeros at step 0, so ParaView
/// keeps the array over time); a bad value is refused at its pointer.
#[test]
fn an_estimating_job_serves_its_indicators() {
    let dir = temp_dir("estimate");
    let srv = Server::start(&dir, 1);
    let a = srv.addr;
    let mut scene = contact_core::scene::presets::get("paper-exp3").unwrap();
    scene["mesh"]["h"] = json!("1/4");
    scene["time"]["k"] = json!("1/4");
    scene["output"] = json!({"every": 2, "estimate": true});
    let r = post_json(a, "/jobs", &scene);
    assert_eq!(r.status, 202, "{}", String::from_utf8_lossy(&r.body));
    let id = r.json()["id"].as_str().unwrap().to_string();
    wait_status(a, &id, &["succeeded"], Duration::from_secs(60));
    let summary = get(a, &format!("/jobs/{id}/summary")).json();
    let run = &summary["estimate"];
    assert!(run["total"].as_f64().unwrap() > 0.0, "{run}");
    for part in ["element", "jump", "traction", "friction", "time"] {
        assert!(run["velocity"][part].is_number(), "{part}");
    }
    assert!(run["damage"]["total"].as_f64().unwrap() > 0.0);
    let steps = summary["steps"].as_array().unwrap();
    assert_eq!(steps.len(), 4);
    assert!(steps
        .iter()
        .all(|s| s["estimate"]["total"].as_f64().unwrap() > 0.0));
    let cells = summary["mesh"]["triangles"].as_u64().unwrap() as usize;
    let f = get(a, &format!("/jobs/{id}/fields?step=last&fields=estimate")).json();
    let eta: Vec<f64> = f["estimate"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(eta.len(), cells);
    // The cell indicators make up the step's total.
    let sum: f64 = eta.iter().map(|e| e * e).sum();
    let total = steps[3]["estimate"]["total"].as_f64().unwrap();
    assert!(
        (sum.sqrt() - total).abs() <= 1e-12 * total,
        "{sum} vs {total}"
    );
    assert!(get(a, &format!("/jobs/{id}/fields?step=last&fields=u"))
        .json()
        .get("estimate")
        .is_none());
    for (file, zero) in [("4.vtu", false), ("0.vtu", true)] {
        let vtu = String::from_utf8(get(a, &format!("/jobs/{id}/fields/{file}")).body).unwrap();
        let xml = roxmltree::Document::parse(&vtu).unwrap();
        let v = vtu_f64s(&xml, "estimate");
        assert_eq!(v.len(), cells, "{file}");
        assert_eq!(v.iter().all(|e| *e == 0.0), zero, "{file}");
    }
    scene["output"]["estimate"] = json!("yes");
    let r = post_json(a, "/jobs", &scene);
    assert_problem(&r, 422);
    assert!(String::from_utf8_lossy(&r.body).contains("/output/estimate"));
}

#[test]
fn study_presets_are_listed_and_served_as_study_requests() {
    let dir = temp_dir("study-presets");
    let srv = Server::start(&dir, 0);
    let a = srv.addr;
    let list = get(a, "/presets").json();
    let names = |key: &str| -> Vec<String> {
        list[key]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| {
                assert_eq!(
                    p["href"],
                    format!("/presets/{}", p["name"].as_str().unwrap())
                );
                assert!(p["description"].as_str().is_some_and(|d| !d.is_empty()));
                p["name"].as_str().unwrap().to_string()
            })
            .collect()
    };
    assert_eq!(names("presets"), contact_core::scene::presets::names());
    assert_eq!(names("studies"), contact_core::study::presets::names());
    for name in contact_core::study::presets::names() {
        let r = get(a, &format!("/presets/{name}"));
        assert_eq!(r.status, 200, "{name}");
        let doc = r.json();
        assert_eq!(
            doc,
            json!({"study": contact_core::study::presets::get(name).unwrap()})
        );
        // The preset's name alone is the same request: the same study, the same document.
        let by_name = post_json(a, "/jobs", &json!({"preset": name}));
        assert_eq!(by_name.status, 202, "{}", by_name.text());
        let by_name = by_name.json();
        assert_eq!(
            (&by_name["kind"], &by_name["scene"]),
            (&json!("study"), &json!(name))
        );
        let first = by_name["id"].as_str().unwrap();
        let c = http(a, "POST", &format!("/jobs/{first}/cancel"), &[], b"");
        assert!(c.status == 200 || c.status == 202, "{}", c.text());
        wait_status(a, first, &["cancelled"], Duration::from_secs(10));
        // A study preset's levels are its own: overrides are refused at their pointer.
        let p = assert_problem(
            &post_json(
                a,
                "/jobs",
                &json!({"preset": name, "overrides": {"h": "1/4"}}),
            ),
            422,
        );
        assert_eq!(p["errors"][0]["pointer"], "/overrides", "{p}");
        // What the page puts in its editor runs as it is.
        let posted = post_json(a, "/jobs", &doc);
        assert_eq!(
            posted.status,
            202,
            "{}",
            String::from_utf8_lossy(&posted.body)
        );
        let job = posted.json();
        assert_eq!(job["kind"], "study");
        assert_eq!(job["scene"], *name);
        let id = job["id"].as_str().unwrap();
        let c = http(a, "POST", &format!("/jobs/{id}/cancel"), &[], b"");
        assert!(c.status == 200 || c.status == 202, "{}", c.text());
        wait_status(a, id, &["cancelled"], Duration::from_secs(10));
    }
    // The convergence preset says what this scheme gives, not only the paper's figure.
    let conv = list["presets"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["name"] == "paper-convergence")
        .unwrap();
    assert!(conv["description"].as_str().unwrap().contains("0.1528"));
    let r = get(a, "/presets/paper-table-3");
    assert_problem(&r, 404);
    assert!(String::from_utf8_lossy(&r.body).contains("paper-table-1"));
    // An unknown name in POST /jobs lists the study presets among the known ones.
    let p = assert_problem(
        &post_json(a, "/jobs", &json!({"preset": "paper-table-3"})),
        422,
    );
    let msg = p["errors"][0]["message"].as_str().unwrap();
    assert!(
        msg.contains("paper-exp1") && msg.contains("paper-table-2"),
        "{msg}"
    );
    srv.stop();
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn bad_input_gets_problem_json_naming_the_field() {
    let dir = temp_dir("errors");
    let srv = Server::start(&dir, 1);
    let a = srv.addr;
    let r = http(
        a,
        "POST",
        "/jobs",
        &[("Content-Type", "application/json")],
        b"{\"mesh\": ",
    );
    assert!(assert_problem(&r, 400)["detail"]
        .as_str()
        .unwrap()
        .contains("malformed JSON"));
    let r = http(a, "POST", "/jobs", &[("Content-Type", "text/plain")], b"{}");
    assert_problem(&r, 415);

    let mut scene = contact_core::scene::presets::get("paper-exp1").unwrap();
    scene["material"]["viscosity"]["eta"] = json!("soft");
    scene["boundary"][1]["to"] = json!([0, 0.5]);
    let p = assert_problem(&post_json(a, "/jobs", &scene), 422);
    let pointers: Vec<&str> = p["errors"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["pointer"].as_str().unwrap())
        .collect();
    assert!(
        pointers.contains(&"/material/viscosity/eta"),
        "{pointers:?}"
    );
    assert!(
        pointers.iter().any(|p| p.starts_with("/boundary/")),
        "{pointers:?}"
    );

    for (body, pointer) in [
        (json!({"preset": "paper-exp9"}), "/preset"),
        (
            json!({"preset": "paper-exp1", "overrides": {"h": "1/512"}}),
            "/overrides/h",
        ),
        (
            json!({"preset": "paper-exp1", "overrides": {"k": "1/0"}}),
            "/overrides/k",
        ),
        // T is the scene's alias of t_end, in overrides too, and errors point at it.
        (
            json!({"preset": "paper-exp1", "overrides": {"T": "-1"}}),
            "/overrides/T",
        ),
        (
            json!({"preset": "paper-exp1", "overrides": {"T": 1, "t_end": 1}}),
            "/overrides/T",
        ),
        (
            json!({"preset": "paper-exp1", "overrides": {"dt": 1}}),
            "/overrides/dt",
        ),
    ] {
        let p = assert_problem(&post_json(a, "/jobs", &body), 422);
        assert_eq!(p["errors"][0]["pointer"], pointer, "{body}");
    }
    // T sets the final time like t_end: the number of steps follows at the preset's k.
    for key in ["T", "t_end"] {
        let r = post_json(
            a,
            "/jobs",
            &json!({"preset": "paper-exp1", "overrides": {"h": "1/2", "k": "1/4", key: "1/2"}}),
        );
        assert!(r.status == 202 || r.status == 200, "{}", r.text());
        let job = r.json();
        let id = job["id"].as_str().unwrap();
        wait_status(a, id, &["succeeded"], Duration::from_secs(30));
        let summary = get(a, &format!("/jobs/{id}/summary")).json();
        assert_eq!(summary["time"]["t_end"], json!(0.5), "{key}");
        assert_eq!(summary["time"]["steps"], json!(2), "{key}");
    }
    // Sent raw: the server answers before it has read the whole body, and closes.
    let big = vec![b' '; 2 << 20];
    let ct = [("Content-Type", "application/json")];
    let r = raw_request(a, "POST", "/jobs", &ct, &big, Duration::from_secs(60)).unwrap();
    assert_eq!(r.status, 413);

    assert_problem(&get(a, "/jobs/00000000-0000-0000-0000-000000000000"), 404);
    assert_problem(&get(a, "/jobs/../../etc/passwd"), 404);
    assert_problem(&get(a, "/jobs/not-a-uuid/summary"), 404);
    assert_problem(&get(a, "/jobs?status=done"), 400);
    assert!(assert_problem(&get(a, "/jobs?colour=red"), 400)["detail"]
        .as_str()
        .unwrap()
        .contains("colour"));
    assert_problem(&get(a, "/nowhere"), 404);
    srv.stop();
    std::fs::remove_dir_all(&dir).ok();
}

/// A key repeated in one object of a body (the last would win in serde_json, the first in
/// other readers) is refused with 422 at its pointer, however it is spelled, and nothing is
/// queued.
#[test]
fn duplicate_keys_are_refused_at_their_pointer() {
    let dir = temp_dir("duplicates");
    let srv = Server::start(&dir, 0);
    let a = srv.addr;
    let ct = [("Content-Type", "application/json")];
    // A whole scene with a second `f0` in `loads`: built from the preset's text, so the rest
    // of the body is a valid scene (the same text without the repeat is accepted below).
    let scene =
        serde_json::to_string(&contact_core::scene::presets::get("paper-exp1").unwrap()).unwrap();
    let loads = "\"loads\":{";
    assert!(scene.contains(loads), "{scene}");
    let twice = scene.replacen(loads, &format!("{loads}\"f0\":[5,5],"), 1);
    let escaped = scene.replacen(loads, &format!("{loads}\"f\\u0030\":[5,5],"), 1);
    for (body, pointer) in [
        (
            r#"{"preset": "paper-exp1", "preset": "paper-exp2"}"#.to_string(),
            "/preset",
        ),
        (
            r#"{"preset": "paper-exp1", "overrides": {"h": "1/4", "h": "1/8"}}"#.to_string(),
            "/overrides/h",
        ),
        (
            r#"{"\u0070reset": "paper-exp1", "preset": "paper-exp2"}"#.to_string(),
            "/preset",
        ),
        (
            r#"{"study": {"preset": "paper-table-1", "preset": "paper-table-2"}}"#.to_string(),
            "/study/preset",
        ),
        (twice, "/loads/f0"),
        (escaped, "/loads/f0"),
    ] {
        let r = http(a, "POST", "/jobs", &ct, body.as_bytes());
        let p = assert_problem(&r, 422);
        assert_eq!(p["errors"][0]["pointer"], pointer, "{body}");
        assert!(
            p["detail"].as_str().unwrap().contains("more than once"),
            "{p}"
        );
    }
    assert_eq!(get(a, "/jobs").json()["jobs"], json!([]));
    // The same scene without the repeat is a job.
    let r = http(a, "POST", "/jobs", &ct, scene.as_bytes());
    assert_eq!(r.status, 202, "{}", r.text());
    srv.stop();
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn idempotency_cancellation_and_unfinished_results() {
    let dir = temp_dir("cancel");
    let srv = Server::start(&dir, 1);
    let a = srv.addr;
    let body = json!({"preset": "paper-exp1", "overrides": {"h": "1/4", "k": "1/4"}}).to_string();
    let h = [
        ("Content-Type", "application/json"),
        ("Idempotency-Key", "k-1"),
    ];
    let first = http(a, "POST", "/jobs", &h, body.as_bytes());
    assert_eq!(first.status, 202);
    let second = http(a, "POST", "/jobs", &h, body.as_bytes());
    assert_eq!(second.json()["id"], first.json()["id"]);
    let other = json!({"preset": "paper-exp1", "overrides": {"h": "1/2"}}).to_string();
    assert_problem(&http(a, "POST", "/jobs", &h, other.as_bytes()), 422);

    // A long job: results are refused while it runs; cancel stops it within a step.
    let r = post_json(a, "/jobs", &long_scene(50_000));
    assert_eq!(r.status, 202);
    let id = r.json()["id"].as_str().unwrap().to_string();
    let running = wait_status(a, &id, &["running"], Duration::from_secs(60));
    assert!(running["links"]["cancel"].is_string());
    let polled = get(a, &format!("/jobs/{id}"));
    assert_eq!(polled.header("retry-after"), Some("1"));
    assert_problem(&get(a, &format!("/jobs/{id}/fields?step=last")), 409);
    assert_problem(&get(a, &format!("/jobs/{id}/summary")), 409);
    assert_problem(&http(a, "DELETE", &format!("/jobs/{id}"), &[], b""), 409);
    assert_eq!(
        http(a, "POST", &format!("/jobs/{id}/cancel"), &[], b"").status,
        202
    );
    let done = wait_status(a, &id, &["cancelled"], Duration::from_secs(10));
    assert!(done["progress"]["step"].as_u64().unwrap() < 50_000);
    let ev = String::from_utf8(get(a, &format!("/jobs/{id}/events")).body).unwrap();
    assert!(ev.contains("\"cancelled\""));
    srv.stop();
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn restart_keeps_results_and_resumes_running_jobs_from_checkpoints() {
    let dir = temp_dir("restart");
    let srv = Server::start(&dir, 1);
    let a = srv.addr;
    let quick = post_json(
        a,
        "/jobs",
        &json!({"preset": "paper-exp3", "overrides": {"h": "1/4", "k": "1/4"}}),
    )
    .json();
    let quick_id = quick["id"].as_str().unwrap().to_string();
    wait_status(a, &quick_id, &["succeeded"], Duration::from_secs(60));
    let quick_summary = get(a, &format!("/jobs/{quick_id}/summary")).body;

    let steps = 30_000;
    let scene = long_scene(steps);
    let long = post_json(a, "/jobs", &scene).json();
    let id = long["id"].as_str().unwrap().to_string();
    wait_status(a, &id, &["running"], Duration::from_secs(60));
    // Let it pass a checkpoint (about once a second), then stop the server mid-run.
    std::thread::sleep(Duration::from_millis(1500));
    let at_stop = get(a, &format!("/jobs/{id}")).json();
    assert_eq!(
        at_stop["status"], "running",
        "the job must still be running when the server stops"
    );
    srv.stop();

    // Read the stored checkpoint from a node without workers: with a worker, the job is
    // claimed at once and its live progress runs ahead of the checkpoint it resumed from.
    let srv = Server::start(&dir, 0);
    let a = srv.addr;
    assert_eq!(
        get(a, &format!("/jobs/{quick_id}/summary")).body,
        quick_summary
    );
    let before = get(a, &format!("/jobs/{id}")).json();
    assert!(
        before["last_checkpoint_step"].as_u64().unwrap_or(0) > 0,
        "no checkpoint before the stop: {before}"
    );
    assert_eq!(
        before["progress"]["step"], before["last_checkpoint_step"],
        "{before}"
    );
    srv.stop();

    let srv = Server::start(&dir, 1);
    let a = srv.addr;
    let done = wait_status(a, &id, &["succeeded", "failed"], Duration::from_secs(300));
    assert_eq!(done["status"], "succeeded", "{done}");
    // Claimed a second time after the restart, and resumed rather than restarted.
    assert_eq!(done["attempt"], 2, "{done}");
    let summary = get(a, &format!("/jobs/{id}/summary")).json();
    assert_eq!(summary["steps"].as_array().unwrap().len(), steps);
    // The second server computed only the steps after the checkpoint.
    let metrics = String::from_utf8(get(a, "/metrics").body).unwrap();
    let computed: usize = metrics
        .lines()
        .find_map(|l| l.strip_prefix("contact_sim_steps_total "))
        .unwrap()
        .parse()
        .unwrap();
    let resumed_at = before["last_checkpoint_step"].as_u64().unwrap() as usize;
    assert_eq!(
        computed,
        steps - resumed_at,
        "resumed from step {resumed_at}"
    );

    // The same result as an uninterrupted run, bit for bit (the checkpoint carries the
    // solvers' warm starts).
    let p = contact_core::scene::validate(&scene).unwrap();
    let straight = contact_core::run::run::<2>(p, Default::default(), |_, _| {
        std::ops::ControlFlow::Continue(())
    })
    .unwrap();
    let last = &summary["final"];
    let fin = straight.final_.unwrap();
    for (key, want) in [("w_V", fin.w_v), ("u_V", fin.u_v), ("zeta_L2", fin.zeta_l2)] {
        assert_eq!(
            last[key].as_f64().unwrap().to_bits(),
            want.to_bits(),
            "{key}: {} vs {want}",
            last[key]
        );
    }
    srv.stop();
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn full_queue_answers_503_with_retry_after() {
    let dir = temp_dir("full");
    // No workers: nothing leaves the queue.
    let srv = Server::start_with(Config {
        data_dir: dir.clone(),
        workers: 0,
        queue_capacity: 1,
        ..Config::default()
    });
    let a = srv.addr;
    assert_eq!(
        post_json(
            a,
            "/jobs",
            &json!({"preset": "paper-exp1", "overrides": {"h": "1/2"}})
        )
        .status,
        202
    );
    let r = post_json(
        a,
        "/jobs",
        &json!({"preset": "paper-exp1", "overrides": {"h": "1/4"}}),
    );
    assert_problem(&r, 503);
    assert_eq!(r.header("retry-after"), Some("5"));
    assert_problem(
        &get(a, "/jobs/00000000-0000-0000-0000-000000000001/events"),
        404,
    );
    srv.stop();
    std::fs::remove_dir_all(&dir).ok();
}

/// A running study stops for a cancel request (`cancelled`) and for a server shutdown
/// (left `running`, to be claimed again: neither failed nor cancelled).
#[test]
fn running_studies_stop_for_cancel_and_shutdown() {
    let dir = temp_dir("study-stop");
    let srv = Server::start(&dir, 1);
    let a = srv.addr;
    // Minutes of work: a reference of 2^14 steps.
    let study = |name: &str| {
        json!({"study": {"scene": "paper-convergence", "name": name, "h": ["1/2", "1/4"],
                         "k": "1/16", "reference": {"h": "1/16", "k": "1/16384"}}})
    };
    let submit = |name: &str| {
        let r = post_json(a, "/jobs", &study(name));
        assert_eq!(r.status, 202, "{}", String::from_utf8_lossy(&r.body));
        let id = r.json()["id"].as_str().unwrap().to_string();
        wait_status(a, &id, &["running"], Duration::from_secs(60));
        // Past the first heartbeat (about once a second).
        std::thread::sleep(Duration::from_millis(1500));
        id
    };
    let cancelled = submit("cancelled");
    assert_eq!(
        http(a, "POST", &format!("/jobs/{cancelled}/cancel"), &[], b"").status,
        202
    );
    let done = wait_status(a, &cancelled, &["cancelled"], Duration::from_secs(10));
    assert!(done["error"].is_null(), "{done}");
    let progress = &done["progress"];
    assert!(
        progress["step"].as_u64().unwrap() < progress["steps"].as_u64().unwrap(),
        "{done}"
    );

    let interrupted = submit("interrupted");
    srv.stop();
    let srv = Server::start(&dir, 0);
    let j = get(srv.addr, &format!("/jobs/{interrupted}")).json();
    assert_eq!(
        (j["status"].as_str(), j["attempt"].as_u64()),
        (Some("running"), Some(1)),
        "{j}"
    );
    srv.stop();
    std::fs::remove_dir_all(&dir).ok();
}

/// Study jobs: submit, table as JSON and text, report SVG, no fields, the shared reference,
/// refusal of non-nested levels; an error estimate on a simulation.
/// A target study over HTTP: the choice and its check in the summary, the chosen run's fields,
/// PVD and archive served like a simulation's, the report; a bad target refused at its
/// pointer; a target out of reach of the budget fails the job with the reason.
#[test]
fn target_studies_over_http() {
    let dir = temp_dir("target");
    let server = Server::start(&dir, 2);
    let a = server.addr;
    let r = post_json(
        a,
        "/jobs",
        &json!({"study": {"scene": "paper-convergence", "target": {"error": 0.2, "quantity": "w"}}}),
    );
    assert_eq!(r.status, 202, "{}", String::from_utf8_lossy(&r.body));
    let id = r.json()["id"].as_str().unwrap().to_string();
    let done = wait_status(a, &id, &["succeeded", "failed"], Duration::from_secs(120));
    assert_eq!(done["status"], "succeeded", "{done}");
    assert_eq!(
        done["links"]["fields"],
        format!("/jobs/{id}/fields?step=last")
    );
    let s = get(a, &format!("/jobs/{id}/summary")).json();
    assert_eq!(s["kind"], "target");
    let chosen = &s["chosen"];
    // The run is the first of the walk whose (2h, 2k) error bar meets the target; the model's
    // prediction only orders the walk, so it is not bounded by the target.
    assert!(chosen["estimated_error"].as_f64().unwrap() <= 0.2, "{s}");
    assert_eq!(chosen["check_passed"], true, "{s}");
    assert!(chosen["predicted_error"].as_f64().unwrap() > 0.0, "{s}");
    assert!(s["error_model"]["h"]["order"].is_number());
    let steps = chosen["steps"].as_u64().unwrap();
    assert_eq!(s["run"]["time"]["steps"], steps, "{}", s["run"]["time"]);
    // The chosen run's last step, its mesh and VTK files.
    let f = get(a, &format!("/jobs/{id}/fields?step=last&mesh=1"));
    assert_eq!(f.status, 200, "{}", String::from_utf8_lossy(&f.body));
    let f = f.json();
    let h = chosen["h"].as_f64().unwrap();
    let n = (1.0 / h).round() as usize;
    assert_eq!(
        f["mesh"]["nodes"].as_array().unwrap().len(),
        (n + 1) * (n + 1)
    );
    assert_eq!(f["n"], steps);
    assert_eq!(get(a, &format!("/jobs/{id}/result.pvd")).status, 200);
    assert_eq!(get(a, &format!("/jobs/{id}/fields/last.vtu")).status, 200);
    assert_eq!(get(a, &format!("/jobs/{id}/archive.tar")).status, 200);
    let svg = String::from_utf8(get(a, &format!("/jobs/{id}/report.svg")).body).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("target"), "{svg}");
    let text = String::from_utf8(get(a, &format!("/jobs/{id}/summary?format=text")).body).unwrap();
    assert!(text.contains("chosen h ="), "{text}");

    let p = assert_problem(
        &post_json(
            a,
            "/jobs",
            &json!({"study": {"scene": "paper-convergence", "target": {"error": 2}}}),
        ),
        422,
    );
    assert_eq!(p["errors"][0]["pointer"], "/study/target/error", "{p}");
    let p = assert_problem(
        &post_json(
            a,
            "/jobs",
            &json!({"study": {"scene": "paper-convergence", "target": {"error": 0.1}, "h": "1/8"}}),
        ),
        422,
    );
    assert_eq!(p["errors"][0]["pointer"], "/study/h", "{p}");

    let r = post_json(
        a,
        "/jobs",
        &json!({"study": {"scene": "paper-convergence", "target": {"error": 0.05}, "budget_s": 0.001}}),
    );
    assert_eq!(r.status, 202);
    let id = r.json()["id"].as_str().unwrap().to_string();
    let done = wait_status(a, &id, &["succeeded", "failed"], Duration::from_secs(60));
    assert_eq!(done["status"], "failed", "{done}");
    let e = &done["error"];
    assert_eq!(e["type"], "/problems/target-unreachable", "{e}");
    assert_eq!(e["errors"][0]["pointer"], "/study/target/error", "{e}");
    let detail = e["detail"].as_str().unwrap();
    assert!(
        detail.contains("cannot be reached") && detail.contains("the budget of 0.001 s"),
        "{e}"
    );
}

/// An adaptive study over HTTP: its cycles in the summary, its final mesh stored as an
/// uploaded mesh of the owner and downloadable, its last cycle served as a simulation on it
/// (fields with the indicators, VTU), the report; a bad θ refused at its pointer.
#[test]
fn adaptive_studies_over_http() {
    let dir = temp_dir("adapt");
    let server = Server::start(&dir, 2);
    let a = server.addr;
    let mut scene = contact_core::scene::presets::get("l-bracket").unwrap();
    scene["mesh"]["h"] = json!("1/4");
    scene["time"] = json!({"t_end": 0.25, "k": "1/16"});
    scene["output"] = json!({"every": 0, "last": true, "fields": ["w", "zeta"]});
    let r = post_json(
        a,
        "/jobs",
        &json!({"study": {"scene": scene, "adapt": {"target": 0.75, "max_nodes": 2000},
                           "reference": {"refine": 2}}}),
    );
    assert_eq!(r.status, 202, "{}", String::from_utf8_lossy(&r.body));
    let id = r.json()["id"].as_str().unwrap().to_string();
    let done = wait_status(a, &id, &["succeeded", "failed"], Duration::from_secs(120));
    assert_eq!(done["status"], "succeeded", "{done}");
    assert_eq!(
        done["links"]["fields"],
        format!("/jobs/{id}/fields?step=last")
    );
    let s = get(a, &format!("/jobs/{id}/summary")).json();
    assert_eq!(s["kind"], "adapt");
    assert_eq!(s["stopped"], "target", "{s}");
    let cycles = s["cycles"].as_array().unwrap();
    assert!(cycles.len() >= 2, "{s}");
    let last = cycles.last().unwrap();
    assert!(last["estimate"].as_f64().unwrap() <= 0.75, "{s}");
    assert!(cycles[0]["error"].as_f64().unwrap() > 0.0, "{s}");
    let nodes = last["nodes"].as_u64().unwrap() as usize;
    assert_eq!(s["summary"]["mesh"]["nodes"], nodes);
    // The final mesh: an uploaded mesh of the caller, with the last cycle's nodes.
    let mesh = s["final_mesh"]["id"].as_str().unwrap();
    let m = get(a, &format!("/meshes/{mesh}")).json();
    assert_eq!(m["summary"]["nodes"], nodes, "{m}");
    let file = get(a, &format!("/meshes/{mesh}/file"));
    assert_eq!(file.status, 200);
    assert!(String::from_utf8(file.body)
        .unwrap()
        .starts_with("$MeshFormat\n2.2"));
    // The last cycle's stored step, on that mesh, with its indicators.
    let f = get(
        a,
        &format!("/jobs/{id}/fields?step=last&mesh=1&fields=w,estimate"),
    );
    assert_eq!(f.status, 200, "{}", String::from_utf8_lossy(&f.body));
    let f = f.json();
    assert_eq!(f["mesh"]["nodes"].as_array().unwrap().len(), nodes);
    assert_eq!(f["n"], 4);
    let eta = f["estimate"].as_array().unwrap();
    assert_eq!(eta.len(), last["cells"].as_u64().unwrap() as usize);
    assert_eq!(get(a, &format!("/jobs/{id}/fields/last.vtu")).status, 200);
    let svg = String::from_utf8(get(a, &format!("/jobs/{id}/report.svg")).body).unwrap();
    assert!(
        svg.starts_with("<svg") && svg.contains("adaptive cycles"),
        "{svg}"
    );
    let text = String::from_utf8(get(a, &format!("/jobs/{id}/summary?format=text")).body).unwrap();
    assert!(
        text.contains("cycle 1") && text.contains("reference"),
        "{text}"
    );

    let p = assert_problem(
        &post_json(
            a,
            "/jobs",
            &json!({"study": {"scene": "l-bracket", "adapt": {"target": 0.1, "theta": 2}}}),
        ),
        422,
    );
    assert_eq!(p["errors"][0]["pointer"], "/study/adapt/theta", "{p}");
}

#[test]
fn study_jobs_and_error_estimates_over_http() {
    let dir = temp_dir("study");
    let server = Server::start(&dir, 2);
    let a = server.addr;
    let study = |k: Value| {
        json!({"study": {"scene": "paper-convergence", "h": ["1/2", "1/4", "1/8"], "k": k,
                         "reference": {"h": "1/16", "k": "1/16"}}})
    };
    let r = post_json(a, "/jobs", &study(json!("1/16")));
    assert_eq!(r.status, 202, "{}", String::from_utf8_lossy(&r.body));
    let job = r.json();
    assert_eq!(job["kind"], "study");
    let id = job["id"].as_str().unwrap().to_string();
    let done = wait_status(a, &id, &["succeeded", "failed"], Duration::from_secs(60));
    assert_eq!(done["status"], "succeeded", "{done}");
    assert_eq!(done["links"]["report"], format!("/jobs/{id}/report.svg"));
    let s = get(a, &format!("/jobs/{id}/summary")).json();
    assert_eq!(s["kind"], "study");
    assert_eq!(s["vary"], "h");
    let rows = s["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 3);
    assert!(rows[0]["order_w"].is_null() && rows[1]["order_w"].is_number());
    for (row, h) in rows.iter().zip([0.5, 0.25, 0.125]) {
        assert_eq!(row["h"], h);
        assert!(row["err_w"].as_f64().unwrap() > 0.0);
        // The maximum over time nodes is at least the error at T.
        assert!(row["err_w_max"].as_f64().unwrap() >= row["err_w"].as_f64().unwrap() * 0.999);
        assert_eq!(row["compared_nodes"], 16);
        assert!(row["worst_residual"].as_f64().unwrap() <= 1e-10);
    }
    assert_eq!(s["reference"]["cached"], false);
    let text = get(a, &format!("/jobs/{id}/summary?format=text"));
    assert_eq!(text.status, 200);
    assert!(text
        .header("content-type")
        .unwrap()
        .starts_with("text/plain"));
    let text = String::from_utf8(text.body).unwrap();
    assert!(text.contains("err_zeta") && text.contains("1/8"), "{text}");
    let svg = get(a, &format!("/jobs/{id}/report.svg"));
    assert_eq!(svg.header("content-type"), Some("image/svg+xml"));
    let svg = String::from_utf8(svg.body).unwrap();
    assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
    assert_eq!(
        svg.matches("<circle").count(),
        2 * 3 + 1,
        "w markers in both panels + legend"
    );
    assert_problem(&get(a, &format!("/jobs/{id}/fields")), 404);
    assert_problem(&get(a, &format!("/jobs/{id}/archive.tar")), 404);

    // A second study of the same scene and reference reuses the reference run.
    let r = post_json(a, "/jobs", &study(json!(["1/2", "1/4", "1/8"])));
    assert_eq!(r.status, 202);
    let id2 = r.json()["id"].as_str().unwrap().to_string();
    wait_status(a, &id2, &["succeeded"], Duration::from_secs(60));
    let s2 = get(a, &format!("/jobs/{id2}/summary")).json();
    assert_eq!(s2["vary"], "hk");
    assert_eq!(s2["reference"]["cached"], true);
    assert_eq!(s2["reference"]["w_V"], s["reference"]["w_V"]);
    // The same study again is answered from the store.
    let again = post_json(a, "/jobs", &study(json!("1/16")));
    assert_eq!(
        (again.status, again.json()["id"].as_str()),
        (200, Some(id.as_str()))
    );

    // Non-nested levels and bad entries are refused at the entry.
    let p = assert_problem(
        &post_json(a, "/jobs", &study(json!(["1/3", "1/16", "1/16"]))),
        422,
    );
    assert_eq!(p["errors"][0]["pointer"], "/study/k/0", "{p}");
    let mut bad = study(json!("1/16"));
    bad["study"]["h"][1] = json!("1/5");
    let p = assert_problem(&post_json(a, "/jobs", &bad), 422);
    assert_eq!(p["errors"][0]["pointer"], "/study/h/1", "{p}");
    assert!(p["errors"][0]["message"]
        .as_str()
        .unwrap()
        .contains("not nested"));
    let p = assert_problem(
        &post_json(a, "/jobs", &json!({"study": {"preset": "paper-table-9"}})),
        422,
    );
    assert_eq!(p["errors"][0]["pointer"], "/study/preset");

    // A simulation with an error bar; format=text and report.svg are for studies only.
    let mut scene = long_scene(16);
    scene["mesh"]["h"] = json!("1/8");
    scene["error_estimate"] = json!(true);
    let r = post_json(a, "/jobs", &scene);
    assert_eq!(r.status, 202, "{}", String::from_utf8_lossy(&r.body));
    let sid = r.json()["id"].as_str().unwrap().to_string();
    wait_status(a, &sid, &["succeeded"], Duration::from_secs(60));
    let sum = get(a, &format!("/jobs/{sid}/summary")).json();
    let est = &sum["error_estimate"];
    assert_eq!(est["coarse_h"], 0.25);
    assert_eq!(est["check"], true);
    let fin = &est["final"];
    assert!(
        fin["w"].as_f64().unwrap() > 0.0 && fin["zeta"].as_f64().unwrap() > 0.0,
        "{est}"
    );
    assert!(fin["observed_order_w"].is_number(), "{est}");
    // Stored steps 4, 8, 12, 16 are coarse time nodes: each gets an estimate.
    let ns: Vec<u64> = est["steps"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["n"].as_u64().unwrap())
        .collect();
    assert_eq!(ns, [4, 8, 12, 16]);
    assert!(sum["stats"]["steps_near_iteration_limit"].is_number());
    assert_problem(&get(a, &format!("/jobs/{sid}/summary?format=text")), 400);
    assert_problem(&get(a, &format!("/jobs/{sid}/report.svg")), 404);
    scene["mesh"]["h"] = json!("1/7");
    let p = assert_problem(&post_json(a, "/jobs", &scene), 422);
    assert_eq!(p["errors"][0]["pointer"], "/error_estimate", "{p}");
    server.stop();
    let _ = std::fs::remove_dir_all(&dir);
}

/// Every `$ref` in `doc` (an OpenAPI document or a schema), with the JSON pointer of the
/// object that holds it.
fn refs(doc: &Value, at: String, out: &mut Vec<(String, String)>) {
    match doc {
        Value::Object(m) => {
            for (k, v) in m {
                match (k.as_str(), v) {
                    ("$ref", Value::String(r)) => out.push((at.clone(), r.clone())),
                    _ => refs(
                        v,
                        format!("{at}/{}", k.replace('~', "~0").replace('/', "~1")),
                        out,
                    ),
                }
            }
        }
        Value::Array(a) => {
            for (i, v) in a.iter().enumerate() {
                refs(v, format!("{at}/{i}"), out);
            }
        }
        _ => {}
    }
}

/// The methods of each route of `app()`, read from its source: `.route("PATH", get(..).post(..))`.
fn router_routes() -> std::collections::BTreeMap<String, std::collections::BTreeSet<String>> {
    let src = include_str!("../src/app.rs");
    let src = src.split(".fallback(").next().unwrap();
    src.split(".route(\"")
        .skip(1)
        .map(|s| {
            let (path, handlers) = s.split_once('"').unwrap();
            let methods = ["get", "post", "put", "patch", "delete"]
                .into_iter()
                .filter(|m| {
                    handlers.match_indices(&format!("{m}(")).any(|(i, _)| {
                        !handlers[..i]
                            .chars()
                            .next_back()
                            .is_some_and(|c| c.is_alphanumeric() || c == '_')
                    })
                })
                .map(String::from)
                .collect();
            // A catch-all `{*file}` is the path parameter `{file}` of the document.
            (path.replace("{*", "{"), methods)
        })
        .collect()
}

/// api/openapi.yaml describes the router: the same routes with the same methods; the query
/// parameters it documents are the ones the handlers take (a documented one with its
/// default, enum or example value is not refused; an undocumented one is); every `$ref`
/// resolves (into this document or into the scene schema it references as
/// `scene.schema.json`), and every link names an operation.
#[test]
fn openapi_describes_the_router() {
    let spec: Value = serde_norway::from_str(include_str!("../api/openapi.yaml")).unwrap();
    let scene: Value = serde_json::from_str(include_str!("../api/scene.schema.json")).unwrap();
    let methods = ["get", "post", "put", "patch", "delete"];
    let paths = spec["paths"].as_object().unwrap();
    let documented: std::collections::BTreeMap<String, std::collections::BTreeSet<String>> = paths
        .iter()
        .map(|(p, item)| {
            let ms = item.as_object().unwrap().keys();
            let ms = ms.filter(|m| methods.contains(&m.as_str())).cloned();
            (p.clone(), ms.collect())
        })
        .collect();
    let routes = router_routes();
    assert!(routes.len() >= 14, "{routes:?}");
    assert_eq!(
        documented, routes,
        "api/openapi.yaml (left) and the router (right) differ"
    );

    let mut all = Vec::new();
    refs(&spec, String::new(), &mut all);
    for (at, r) in &all {
        let target = match r.split_once('#') {
            Some(("", ptr)) => spec.pointer(ptr),
            Some(("scene.schema.json", ptr)) => scene.pointer(ptr),
            None if r == "scene.schema.json" => Some(&scene),
            _ => None,
        };
        assert!(target.is_some(), "{at}: $ref {r} does not resolve");
    }
    let mut ids = std::collections::BTreeSet::new();
    for item in paths.values() {
        for (m, op) in item.as_object().unwrap() {
            if methods.contains(&m.as_str()) {
                let id = op["operationId"]
                    .as_str()
                    .expect("every operation has an id");
                assert!(ids.insert(id.to_string()), "operationId {id} is used twice");
            }
        }
    }
    for (name, link) in spec["components"]["links"].as_object().unwrap() {
        let id = link["operationId"].as_str().unwrap();
        assert!(ids.contains(id), "link {name} names no operation ({id})");
    }

    let dir = temp_dir("openapi");
    let srv = Server::start(&dir, 0);
    let fill = |p: &str| {
        p.replace("{id}", "00000000-0000-0000-0000-000000000000")
            .replace("{file}", "last.vtu")
            .replace("{name}", "paper-exp1")
    };
    for (path, item) in paths {
        for (m, op) in item.as_object().unwrap() {
            let query: Vec<&Value> = op["parameters"]
                .as_array()
                .into_iter()
                .flatten()
                .filter(|p| p["in"] == "query")
                .collect();
            if query.is_empty() {
                continue;
            }
            let method = m.to_uppercase();
            for p in query {
                let (name, schema) = (p["name"].as_str().unwrap(), &p["schema"]);
                let value = [&schema["default"], &schema["enum"][0], &schema["example"]]
                    .into_iter()
                    .find(|v| !v.is_null())
                    .unwrap_or_else(|| panic!("{path} {name}: no default, enum or example"));
                let value = value.as_str().map_or(value.to_string(), String::from);
                let url = format!("{}?{name}={value}", fill(path));
                let r = http(srv.addr, &method, &url, &[], b"");
                assert_ne!(r.status, 400, "{method} {url}: {}", r.text());
            }
            let url = format!("{}?undocumented=1", fill(path));
            assert_problem(&http(srv.addr, &method, &url, &[], b""), 400);
        }
    }
    srv.stop();
    std::fs::remove_dir_all(&dir).ok();
}

/// A job whose predicted peak exceeds the node's `--max-job-memory` is refused at
/// submission, before any numeric work: at /solver/linear when the direct path is demanded,
/// at the mesh when no path fits; `auto` under a limit only multigrid meets is accepted.
#[test]
fn a_job_over_the_memory_limit_is_refused_at_submission() {
    let mut box_scene = contact_core::scene::presets::get("box-exp3").unwrap();
    box_scene["mesh"]["h"] = json!("1/24");
    box_scene["time"] = json!({"t_end": 1, "N": 1});
    let problem = contact_core::scene::validate(&box_scene).unwrap();
    let predicted = contact_core::memory::predict(&problem);
    let dir = temp_dir("memory");
    let s = Server::start_with(Config {
        data_dir: dir.clone(),
        workers: 0,
        max_job_memory: Some(predicted.multigrid),
        ..Config::default()
    });
    let a = s.addr;
    box_scene["solver"] = json!({"linear": "direct"});
    let p = assert_problem(&post_json(a, "/jobs", &box_scene), 422);
    assert_eq!(p["errors"][0]["pointer"], "/solver/linear", "{p}");
    let msg = p["errors"][0]["message"].as_str().unwrap();
    assert!(
        msg.contains("per-job limit") && msg.contains("multigrid"),
        "{msg}"
    );
    box_scene["solver"] = json!({"linear": "auto"});
    let r = post_json(a, "/jobs", &box_scene);
    assert_eq!(r.status, 202, "{}", r.text());
    box_scene["mesh"]["h"] = json!("1/32");
    let p = assert_problem(&post_json(a, "/jobs", &box_scene), 422);
    assert_eq!(p["errors"][0]["pointer"], "/mesh/h", "{p}");
    s.stop();
    let _ = std::fs::remove_dir_all(&dir);
}

/// A study meets the per-job memory limit a job meets, at submission: box-exp3 with the
/// direct solver demanded, refused as a job at h = 1/24, is refused as the reference of a
/// ladder study (at `/study/reference/h`) and as a target study whose pilots need that much
/// (at `/study/scene`), with the predicted and allowed bytes in the problem's `limit`; a larger
/// limit admits it, and the job resource shows the largest run's prediction.
#[test]
fn a_study_over_the_memory_limit_is_refused_at_submission_like_a_job() {
    let mut scene = contact_core::scene::presets::get("box-exp3").unwrap();
    scene["solver"] = json!({"linear": "direct"});
    let mut reference = scene.clone();
    reference["mesh"]["h"] = json!("1/24");
    reference["time"] = json!({"t_end": 1, "k": "1/8"});
    let predicted =
        contact_core::memory::predict(&contact_core::scene::validate(&reference).unwrap()).direct;
    let ladder = json!({"study": {"scene": scene, "h": ["1/4", "1/8"], "k": "1/8",
                                  "reference": {"h": "1/24", "k": "1/8"}}});
    for (limit, admitted) in [(predicted - 1, false), (predicted, true)] {
        let dir = temp_dir("study-memory");
        let s = Server::start_with(Config {
            data_dir: dir.clone(),
            workers: 0,
            max_job_memory: Some(limit),
            ..Config::default()
        });
        let a = s.addr;
        // The job alone.
        let r = post_json(a, "/jobs", &reference);
        assert_eq!(r.status == 202, admitted, "{}", r.text());
        let r = post_json(a, "/jobs", &ladder);
        if admitted {
            assert_eq!(r.status, 202, "{}", r.text());
            let id = r.json()["id"].as_str().unwrap().to_string();
            let job = get(a, &format!("/jobs/{id}")).json();
            assert_eq!(
                job["memory"],
                json!({"predicted_bytes": predicted, "limit_bytes": limit, "linear_path": "direct"}),
                "{job}"
            );
        } else {
            let p = assert_problem(&r, 422);
            assert_eq!(p["errors"][0]["pointer"], "/study/reference/h", "{p}");
            assert_eq!(
                p["limit"],
                json!({"name": "memory", "pointer": "/study/reference/h",
                       "needed": predicted, "allowed": limit}),
                "{p}"
            );
            let msg = p["detail"].as_str().unwrap();
            assert!(
                msg.starts_with("the reference (h = 1/24, k = 1/8): the direct solver needs"),
                "{msg}"
            );
        }
        s.stop();
        let _ = std::fs::remove_dir_all(&dir);
    }
    // A target study: its finest first pilot (h = 1/8 at the coarsest n0 = 2, 16 steps).
    let Ok((contact_core::study::request::Request::Target { spec, .. }, _)) =
        contact_core::study::request::parse(
            &json!({"scene": scene, "target": {"error": 0.1}}),
            "/study",
            &contact_core::scene::Bundled,
        )
    else {
        panic!("a target study")
    };
    let finest = *spec.first_pilots().iter().max().unwrap();
    let pilot = contact_core::study::with_resolution(&spec.base, finest);
    let predicted = contact_core::memory::predict(&pilot).direct;
    let dir = temp_dir("target-memory");
    let s = Server::start_with(Config {
        data_dir: dir.clone(),
        workers: 0,
        max_job_memory: Some(predicted - 1),
        ..Config::default()
    });
    let p = assert_problem(
        &post_json(
            s.addr,
            "/jobs",
            &json!({"study": {"scene": scene, "target": {"error": 0.1}}}),
        ),
        422,
    );
    assert_eq!(p["errors"][0]["pointer"], "/study/scene", "{p}");
    assert_eq!(p["limit"]["needed"], json!(predicted), "{p}");
    s.stop();
    let _ = std::fs::remove_dir_all(&dir);
}

/// The job resource shows the memory predicted at submission: for a simulation, the bytes
/// `contact_core::memory::choose` predicts for the validated scene under the server's
/// per-job limit, that limit, and the path; for a study, its reference's (its largest run).
#[test]
fn the_job_resource_shows_the_predicted_memory() {
    let limit = 1 << 30;
    let mut scene = contact_core::scene::presets::get("paper-convergence").unwrap();
    contact_core::scene::apply_overrides(
        &mut scene,
        &contact_core::scene::Overrides {
            h: Some(json!("1/8")),
            k: Some(json!("1/8")),
            ..Default::default()
        },
    );
    let problem = contact_core::scene::validate(&scene).unwrap();
    let (_, predicted) = contact_core::memory::choose(&problem, Some(limit)).unwrap();
    let dir = temp_dir("predicted-memory");
    let s = Server::start_with(Config {
        data_dir: dir.clone(),
        workers: 0,
        max_job_memory: Some(limit),
        ..Config::default()
    });
    let a = s.addr;
    let r = post_json(
        a,
        "/jobs",
        &json!({"preset": "paper-convergence", "overrides": {"h": "1/8", "k": "1/8"}}),
    );
    assert_eq!(r.status, 202, "{}", r.text());
    let id = r.json()["id"].as_str().unwrap().to_string();
    let job = get(a, &format!("/jobs/{id}")).json();
    assert_eq!(
        job["memory"],
        json!({"predicted_bytes": predicted, "limit_bytes": limit, "linear_path": "direct"}),
        "{job}"
    );
    assert!(predicted > 0 && predicted <= limit);
    let listed = get(a, "/jobs").json();
    assert_eq!(listed["jobs"][0]["memory"], job["memory"], "{listed}");

    let r = post_json(a, "/jobs", &json!({"preset": "paper-table-1"}));
    assert_eq!(r.status, 202, "{}", r.text());
    let id = r.json()["id"].as_str().unwrap().to_string();
    let study = get(a, &format!("/jobs/{id}")).json();
    assert_eq!(study["kind"], "study");
    let (plan, _) = contact_core::study::parse(&json!({"preset": "paper-table-1"}), "").unwrap();
    let (path, reference) = contact_core::memory::choose(&plan.base, Some(limit)).unwrap();
    assert_eq!(
        study["memory"],
        json!({"predicted_bytes": reference, "limit_bytes": limit, "linear_path": path}),
        "{study}"
    );
    s.stop();
    let _ = std::fs::remove_dir_all(&dir);
}
