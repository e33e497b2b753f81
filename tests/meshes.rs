//! Uploaded meshes over real HTTP on an ephemeral port: `POST /meshes` (ASCII and binary
//! gmsh files, summaries checked against counts read from the file here, idempotent
//! re-uploads, limits, hostile files), `GET /meshes` paging, the file download, jobs on an
//! uploaded mesh (results on the mesh, the store's answer for a repeated scene, unknown ids),
//! and `DELETE /meshes/{id}` refused while a queued or running job uses the mesh.

use contact_sim::Config;
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

mod common;
use common::http::{assert_problem, get, http, post_json, raw_request, wait_status, Resp};
use common::server::Server;

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("contact-sim-meshes-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// A test mesh of the core: the presets' meshes, else the reader's test files.
fn test_mesh(name: &str) -> Vec<u8> {
    let core = Path::new(env!("CARGO_MANIFEST_DIR")).join("crates/contact-core");
    let p = core.join("preset-meshes").join(name);
    let p = if p.exists() {
        p
    } else {
        core.join("tests/meshes").join(name)
    };
    std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

const OCTET: (&str, &str) = ("Content-Type", "application/octet-stream");

fn upload(a: std::net::SocketAddr, bytes: &[u8]) -> Resp {
    http(a, "POST", "/meshes", &[OCTET], bytes)
}

/// An upload the server may refuse before reading it all (413): written on a raw socket,
/// which ignores the write error of a connection closed early.
fn upload_raw(a: std::net::SocketAddr, bytes: &[u8]) -> Resp {
    raw_request(
        a,
        "POST",
        "/meshes",
        &[OCTET],
        bytes,
        Duration::from_secs(60),
    )
    .unwrap_or_else(|e| panic!("POST /meshes: {e}"))
}

fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// What an ASCII MSH 4.1 file declares, read here independently of the service's reader:
/// the node count of the `$Nodes` header, the triangles of the `$Elements` blocks of type 2,
/// and per named physical group of dimension 1 the number of line elements (type 1) in the
/// curves tagged with it.
struct Declared {
    nodes: usize,
    triangles: usize,
    groups: BTreeMap<String, usize>,
}

fn declared(text: &str) -> Declared {
    let section = |name: &str| -> Vec<&str> {
        let start = text
            .find(&format!("${name}\n"))
            .unwrap_or_else(|| panic!("no ${name}"));
        let end = text.find(&format!("$End{name}")).unwrap();
        text[start..end].lines().skip(1).collect()
    };
    let nums = |line: &str| -> Vec<i64> {
        line.split_whitespace()
            .map(|w| w.parse::<f64>().unwrap() as i64)
            .collect()
    };
    let nodes = nums(section("Nodes")[0])[1] as usize;
    // Physical names of dimension 1.
    let mut names = BTreeMap::new();
    for line in &section("PhysicalNames")[1..] {
        let mut parts = line.splitn(3, ' ');
        let dim: i64 = parts.next().unwrap().parse().unwrap();
        let tag: i64 = parts.next().unwrap().parse().unwrap();
        let name = parts.next().unwrap().trim_matches('"').to_string();
        if dim == 1 {
            names.insert(tag, name);
        }
    }
    // Curves: tag, bounding box (6), physical tags.
    let entities = section("Entities");
    let counts = nums(entities[0]);
    let mut curve_tags: BTreeMap<i64, Vec<i64>> = BTreeMap::new();
    for line in &entities[1 + counts[0] as usize..1 + (counts[0] + counts[1]) as usize] {
        let v = nums(line);
        let n = v[7] as usize;
        curve_tags.insert(v[0], v[8..8 + n].to_vec());
    }
    let elements = section("Elements");
    let mut triangles = 0;
    let mut groups: BTreeMap<String, usize> = names.values().map(|n| (n.clone(), 0)).collect();
    let mut i = 1;
    while i < elements.len() {
        let h = nums(elements[i]);
        let (dim, entity, kind, count) = (h[0], h[1], h[2], h[3] as usize);
        if kind == 2 {
            triangles += count;
        }
        if dim == 1 && kind == 1 {
            for tag in &curve_tags[&entity] {
                if let Some(name) = names.get(tag) {
                    *groups.get_mut(name).unwrap() += count;
                }
            }
        }
        i += 1 + count;
    }
    Declared {
        nodes,
        triangles,
        groups,
    }
}

/// An ASCII MSH 4.1 file of the rectangle [0, 2] × [0, 1] cut into nx × ny squares of two
/// triangles each, its left side "clamped", its bottom "contact", its top "traction".
fn rectangle_msh(nx: usize, ny: usize) -> Vec<u8> {
    use std::fmt::Write;
    let node = |i: usize, j: usize| 1 + j * (nx + 1) + i;
    let n = (nx + 1) * (ny + 1);
    let mut s = String::with_capacity(64 * n);
    s += "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n";
    s += "$PhysicalNames\n4\n1 1 \"clamped\"\n1 2 \"contact\"\n1 3 \"traction\"\n2 4 \"body\"\n$EndPhysicalNames\n";
    s += "$Entities\n0 3 1 0\n1 0 0 0 0 1 0 1 1 0\n2 0 0 0 2 0 0 1 2 0\n3 0 1 0 2 1 0 1 3 0\n1 0 0 0 2 1 0 1 4 0\n$EndEntities\n";
    let _ = write!(s, "$Nodes\n1 {n} 1 {n}\n2 1 0 {n}\n");
    for k in 1..=n {
        let _ = writeln!(s, "{k}");
    }
    for j in 0..=ny {
        for i in 0..=nx {
            let _ = writeln!(
                s,
                "{} {} 0",
                2.0 * i as f64 / nx as f64,
                j as f64 / ny as f64
            );
        }
    }
    s += "$EndNodes\n";
    let cells = 2 * nx * ny;
    let total = ny + 2 * nx + cells;
    let _ = write!(s, "$Elements\n4 {total} 1 {total}\n");
    let mut tag = 0;
    let mut next = || {
        tag += 1;
        tag
    };
    let _ = writeln!(s, "1 1 1 {ny}");
    for j in 0..ny {
        let _ = writeln!(s, "{} {} {}", next(), node(0, j), node(0, j + 1));
    }
    let _ = writeln!(s, "1 2 1 {nx}");
    for i in 0..nx {
        let _ = writeln!(s, "{} {} {}", next(), node(i, 0), node(i + 1, 0));
    }
    let _ = writeln!(s, "1 3 1 {nx}");
    for i in 0..nx {
        let _ = writeln!(s, "{} {} {}", next(), node(i, ny), node(i + 1, ny));
    }
    let _ = writeln!(s, "2 1 2 {cells}");
    for j in 0..ny {
        for i in 0..nx {
            let (a, b, c, d) = (
                node(i, j),
                node(i + 1, j),
                node(i + 1, j + 1),
                node(i, j + 1),
            );
            let _ = writeln!(s, "{} {a} {b} {c}", next());
            let _ = writeln!(s, "{} {a} {c} {d}", next());
        }
    }
    s += "$EndElements\n";
    s.into_bytes()
}

#[test]
fn upload_summaries_listing_and_files() {
    let dir = temp_dir("upload");
    // A request body limit below the plate's size: mesh uploads have their own limit.
    let srv = Server::start_with(Config {
        data_dir: dir.clone(),
        workers: 0,
        max_body_bytes: 16 << 10,
        max_mesh_bytes: 256 << 10,
        ..Config::default()
    });
    let a = srv.addr;
    let ascii = test_mesh("plate-with-hole.msh");
    let binary = test_mesh("plate-with-hole-binary.msh");
    assert!(ascii.len() > 16 << 10 && binary.len() > 16 << 10);
    let want = declared(std::str::from_utf8(&ascii).unwrap());
    assert_eq!(
        (want.nodes, want.triangles),
        (406, 724),
        "the file as read here"
    );

    let t = Instant::now();
    let r = upload(a, &ascii);
    let upload_s = t.elapsed().as_secs_f64();
    assert_eq!(r.status, 201, "{}", r.text());
    let m = r.json();
    let id = sha256_hex(&ascii);
    assert_eq!(m["id"], id.as_str());
    assert_eq!(r.header("location"), Some(format!("/meshes/{id}").as_str()));
    assert_eq!(r.header("content-type"), Some("application/json"));
    assert_eq!(m["bytes"], ascii.len());
    assert!(m["created_at"].as_str().unwrap().ends_with('Z'));
    assert_eq!(m["links"]["file"], format!("/meshes/{id}/file").as_str());
    let s = &m["summary"];
    assert_eq!(s["dimension"], 2);
    assert_eq!(s["nodes"], want.nodes);
    assert_eq!(s["cells"], want.triangles);
    let groups: BTreeMap<String, u64> = s["groups"]
        .as_array()
        .unwrap()
        .iter()
        .map(|g| {
            (
                g["name"].as_str().unwrap().into(),
                g["facets"].as_u64().unwrap(),
            )
        })
        .collect();
    let want_groups: BTreeMap<String, u64> = want
        .groups
        .iter()
        .map(|(k, v)| (k.clone(), *v as u64))
        .collect();
    assert_eq!(groups, want_groups);
    // Every boundary facet is in one of the plate's groups; the outer ones measure the sides.
    let facets: u64 = groups.values().sum();
    assert_eq!(s["boundary_facets"], facets);
    let measure = |name: &str| {
        s["groups"]
            .as_array()
            .unwrap()
            .iter()
            .find(|g| g["name"] == name)
            .unwrap()["measure"]
            .as_f64()
            .unwrap()
    };
    assert!((measure("contact") - 2.0).abs() < 1e-12);
    assert!((measure("clamped") - 1.0).abs() < 1e-12);
    assert!((measure("hole") - 2.0 * std::f64::consts::PI * 0.2).abs() < 0.01);
    assert_eq!(
        s["bounding_box"],
        json!({"min": [0.0, 0.0], "max": [2.0, 1.0]})
    );
    for k in [
        "min_cell_size",
        "mean_cell_size",
        "max_cell_size",
        "min_quality",
        "mean_quality",
    ] {
        assert!(s[k].as_f64().unwrap() > 0.0, "{k}: {s}");
    }

    // The binary file of the same mesh: another id, the same figures.
    let r = upload(a, &binary);
    assert_eq!(r.status, 201, "{}", r.text());
    let mb = r.json();
    assert_eq!(mb["id"], sha256_hex(&binary).as_str());
    assert_ne!(mb["id"], m["id"]);
    for k in [
        "dimension",
        "nodes",
        "cells",
        "boundary_facets",
        "groups",
        "bounding_box",
    ] {
        assert_eq!(mb["summary"][k], s[k], "{k}");
    }

    // Uploading the same bytes again: 200, the same record; nothing is added.
    let r = upload(a, &ascii);
    assert_eq!(r.status, 200, "{}", r.text());
    assert_eq!(r.json(), m);
    assert_eq!(r.header("location"), Some(format!("/meshes/{id}").as_str()));
    assert_eq!(get(a, &format!("/meshes/{id}")).json(), m);

    // The file, byte for byte, with its SHA-256 (the id).
    let f = get(a, &format!("/meshes/{id}/file"));
    assert_eq!(f.status, 200);
    assert_eq!(f.body, ascii);
    assert_eq!(f.header("content-type"), Some("application/octet-stream"));
    assert_eq!(f.header("etag"), Some(format!("\"{id}\"").as_str()));
    assert!(f.header("repr-digest").unwrap().starts_with("sha-256=:"));
    assert!(f
        .header("content-disposition")
        .unwrap()
        .contains(&format!("{id}.msh")));

    // The example of api/openapi.yaml is a mesh.
    let spec: Value = serde_norway::from_str(include_str!("../api/openapi.yaml")).unwrap();
    let example = spec["paths"]["/meshes"]["post"]["requestBody"]["content"]
        ["application/octet-stream"]["example"]
        .as_str()
        .unwrap();
    let r = upload(a, example.as_bytes());
    assert_eq!(r.status, 201, "{}", r.text());
    assert_eq!(r.json()["summary"]["cells"], 2);
    assert_eq!(
        http(
            a,
            "DELETE",
            &format!("/meshes/{}", r.json()["id"].as_str().unwrap()),
            &[],
            b""
        )
        .status,
        204
    );

    // Two more: the arch and a 3D mesh (stored, summarised in 3D).
    let arch = test_mesh("arch-on-support.msh");
    let r = upload(a, &arch);
    assert_eq!(r.status, 201, "{}", r.text());
    let cylinder = test_mesh("cylinder.msh");
    let r = upload(a, &cylinder);
    assert_eq!(r.status, 201, "{}", r.text());
    let c = r.json();
    assert_eq!(c["summary"]["dimension"], 3);
    assert_eq!(
        c["summary"]["bounding_box"]["min"]
            .as_array()
            .unwrap()
            .len(),
        3
    );

    // Listing: newest first, pages of 3 with a next link (also as Link).
    let newest_first = [
        sha256_hex(&cylinder),
        sha256_hex(&arch),
        sha256_hex(&binary),
        id.clone(),
    ];
    let p1 = get(a, "/meshes?limit=3");
    assert_eq!(p1.status, 200);
    let next = p1.json()["next"].as_str().unwrap().to_string();
    assert_eq!(
        p1.header("link"),
        Some(format!("<{next}>; rel=\"next\"").as_str())
    );
    let p2 = get(a, &next).json();
    assert!(p2["next"].is_null());
    let listed: Vec<String> = p1.json()["meshes"]
        .as_array()
        .unwrap()
        .iter()
        .chain(p2["meshes"].as_array().unwrap())
        .map(|m| m["id"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(listed, newest_first);
    assert_eq!(get(a, "/meshes").json()["meshes"][3], m);

    // Errors: unknown and malformed ids, bad paging, media types, size.
    let unknown = "0".repeat(64);
    for path in [
        format!("/meshes/{unknown}"),
        format!("/meshes/{unknown}/file"),
        format!("/meshes/{}", id.to_uppercase()),
        "/meshes/plate-with-hole.msh".into(),
        "/meshes/..%2F..%2Fjobs.sqlite3".into(),
    ] {
        assert_problem(&get(a, &path), 404);
    }
    assert_problem(
        &http(a, "DELETE", &format!("/meshes/{unknown}"), &[], b""),
        404,
    );
    for q in [
        "limit=0",
        "limit=501",
        "cursor=x",
        "cursor=s0",
        "status=queued",
    ] {
        assert_problem(&get(a, &format!("/meshes?{q}")), 400);
    }
    for ct in [
        "application/json",
        "text/plain",
        "application/x-www-form-urlencoded",
        "multipart/form-data; boundary=x",
    ] {
        let p = assert_problem(
            &http(a, "POST", "/meshes", &[("Content-Type", ct)], &ascii),
            415,
        );
        assert!(p["detail"]
            .as_str()
            .unwrap()
            .contains("application/octet-stream"));
    }
    // Parameters of the media type are fine.
    let r = http(
        a,
        "POST",
        "/meshes",
        &[("Content-Type", "Application/Octet-Stream; x=1")],
        &ascii,
    );
    assert_eq!(r.status, 200, "{}", r.text());
    let p = assert_problem(&upload_raw(a, &vec![b' '; 300 << 10]), 413);
    assert!(!p["detail"].as_str().unwrap().is_empty());
    // The other bodies keep their limit.
    let body = json!({"name": "x".repeat(20 << 10)}).to_string();
    let r = raw_request(
        a,
        "POST",
        "/jobs",
        &[("Content-Type", "application/json")],
        body.as_bytes(),
        Duration::from_secs(60),
    )
    .unwrap();
    assert_problem(&r, 413);

    // Deleted: gone from everywhere, files included; uploaded again, it is new.
    assert_eq!(
        http(a, "DELETE", &format!("/meshes/{id}"), &[], b"").status,
        204
    );
    assert_problem(&get(a, &format!("/meshes/{id}")), 404);
    assert_problem(&get(a, &format!("/meshes/{id}/file")), 404);
    assert_problem(&http(a, "DELETE", &format!("/meshes/{id}"), &[], b""), 404);
    assert!(!dir.join("meshes").join(format!("{id}.msh")).exists());
    assert_eq!(
        get(a, "/meshes").json()["meshes"].as_array().unwrap().len(),
        3
    );
    assert_eq!(upload(a, &ascii).status, 201);

    // A bigger mesh: 200 × 100 squares, 40,000 triangles; over this server's mesh limit,
    // within the default one.
    let big = rectangle_msh(200, 100);
    assert_problem(&upload_raw(a, &big), 413);
    srv.stop();
    let srv = Server::start_with(Config {
        data_dir: dir.clone(),
        workers: 0,
        ..Config::default()
    });
    let t = Instant::now();
    let r = upload(srv.addr, &big);
    let big_s = t.elapsed().as_secs_f64();
    assert_eq!(r.status, 201, "{}", r.text());
    let s = &r.json()["summary"];
    assert_eq!(
        (s["nodes"].as_u64(), s["cells"].as_u64()),
        (Some(201 * 101), Some(40_000))
    );
    assert_eq!(s["boundary_facets"], 2 * (200 + 100));
    // The data directory survived the restart: the meshes are still listed.
    assert_eq!(
        get(srv.addr, "/meshes").json()["meshes"]
            .as_array()
            .unwrap()
            .len(),
        5
    );
    eprintln!(
        "upload + check of plate-with-hole.msh ({} bytes, 406 nodes): {:.1} ms; of a 40,000-triangle rectangle ({} bytes): {:.0} ms",
        ascii.len(),
        upload_s * 1e3,
        big.len(),
        big_s * 1e3
    );
    srv.stop();
    let _ = std::fs::remove_dir_all(&dir);
}

/// Files that are not usable meshes: a 4xx naming what is wrong, never a 5xx, and nothing
/// stored.
#[test]
fn hostile_uploads_are_refused_with_a_reason() {
    let dir = temp_dir("hostile");
    let srv = Server::start_with(Config {
        data_dir: dir.clone(),
        workers: 0,
        submit_rate: 0.0,
        ..Config::default()
    });
    let a = srv.addr;
    let ascii = String::from_utf8(test_mesh("plate-with-hole.msh")).unwrap();
    let binary = test_mesh("plate-with-hole-binary.msh");
    // The second triangle (cell 1) of the first block of triangles.
    let triangle_line = {
        let el = ascii.find("$Elements\n").unwrap();
        let block = ascii[el..]
            .lines()
            .position(|l| {
                let v: Vec<&str> = l.split_whitespace().collect();
                v.len() == 4 && v[0] == "2" && v[2] == "2"
            })
            .unwrap();
        ascii[el..].lines().nth(block + 2).unwrap().to_string()
    };
    let tri: Vec<&str> = triangle_line.split_whitespace().collect();
    let reversed = format!("{} {} {} {}", tri[0], tri[1], tri[3], tri[2]);
    let missing = format!("{} {} {} 99999", tri[0], tri[1], tri[2]);
    let cases: Vec<(&str, Vec<u8>, u16, &[&str])> = vec![
        ("empty body", Vec::new(), 422, &["empty"]),
        (
            "truncated",
            ascii.as_bytes()[..ascii.len() / 2].to_vec(),
            422,
            &["truncated"],
        ),
        (
            "truncated binary",
            binary[..binary.len() * 2 / 3].to_vec(),
            422,
            &["$Elements", "remaining"],
        ),
        (
            "version 3.0",
            ascii.replacen("4.1 0 8", "3.0 0 8", 1).into_bytes(),
            422,
            &["3.0", "4.1", "2.2"],
        ),
        (
            "NaN coordinate",
            ascii.replacen("\n0 0 0\n", "\nnan 0 0\n", 1).into_bytes(),
            422,
            &["$Nodes", "line"],
        ),
        (
            "huge node count",
            ascii
                .replacen(
                    "17 406 1 406",
                    "17 999999999999999999 1 999999999999999999",
                    1,
                )
                .into_bytes(),
            422,
            &["$Nodes"],
        ),
        (
            "huge element count",
            ascii
                .replacen("9 812 1 812", "9 18446744073709551615 1 812", 1)
                .into_bytes(),
            422,
            &["$Elements"],
        ),
        (
            "second-order triangles",
            test_mesh("square-order2-msh22.msh"),
            422,
            &["6-node second-order triangle", "gmsh -order 1"],
        ),
        (
            "missing node",
            ascii.replacen(&triangle_line, &missing, 1).into_bytes(),
            422,
            &["99999"],
        ),
        (
            "not a mesh",
            b"\x00\x01 hello, this is not gmsh".to_vec(),
            422,
            &["$MeshFormat"],
        ),
        (
            "JSON",
            br#"{"domain": {"mesh": "plate.msh"}}"#.to_vec(),
            422,
            &["$MeshFormat"],
        ),
    ];
    for (what, body, status, words) in &cases {
        let r = upload(a, body);
        let p = assert_problem(&r, *status);
        let detail = p["detail"].as_str().unwrap();
        for w in *words {
            assert!(detail.contains(w), "{what}: {detail:?} lacks {w:?}");
        }
        eprintln!("{what}: {status} {detail}");
    }
    // A cell listed in the other orientation is a labelling, not a fault: stored, counted.
    let r = upload(a, ascii.replacen(&triangle_line, &reversed, 1).as_bytes());
    assert_eq!(r.status, 201, "{}", r.text());
    assert_eq!(r.json()["summary"]["negatively_oriented_cells"], 1);
    // Wrong media types, whatever the bytes.
    for ct in ["application/json", "text/plain", "image/png"] {
        assert_problem(
            &http(
                a,
                "POST",
                "/meshes",
                &[("Content-Type", ct)],
                ascii.as_bytes(),
            ),
            415,
        );
    }
    // Random bytes and random damage to a good file: never a 5xx.
    let mut rng = 0x2545_f491_4f6c_dd1du64;
    let mut next = || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        rng
    };
    let mut statuses = BTreeMap::new();
    for i in 0..150 {
        let mut body = if i % 3 == 0 {
            binary.clone()
        } else {
            ascii.as_bytes().to_vec()
        };
        if i % 5 == 4 {
            body = (0..(next() % 4096)).map(|_| next() as u8).collect();
        } else {
            for _ in 0..1 + next() % 4 {
                let at = (next() as usize) % body.len();
                body[at] = next() as u8;
            }
        }
        let r = upload(a, &body);
        assert!(
            (200..500).contains(&r.status),
            "damaged upload {i}: {} {}",
            r.status,
            r.text()
        );
        *statuses.entry(r.status).or_insert(0) += 1;
    }
    eprintln!("150 damaged or random uploads: {statuses:?}");
    // Nothing refused was stored (the one stored before: the copy with a reversed cell).
    let stored = get(a, "/meshes").json()["meshes"].as_array().unwrap().len();
    assert_eq!(stored, 1 + statuses.get(&201).copied().unwrap_or(0));
    let files = std::fs::read_dir(dir.join("meshes")).unwrap().count();
    assert_eq!(files, stored);
    assert_eq!(get(a, "/healthz").status, 200);
    srv.stop();
    let _ = std::fs::remove_dir_all(&dir);
}

/// The plate-with-hole preset on the uploaded mesh `id`, under `name`, with `steps` steps
/// over t_end = 1 storing only the last.
/// Submits a study, waits for it to succeed and returns the rows of its table.
fn study_rows(a: std::net::SocketAddr, study: &Value) -> Vec<Value> {
    let r = post_json(a, "/jobs", study);
    assert_eq!(r.status, 202, "{}", r.text());
    let id = r.json()["id"].as_str().unwrap().to_string();
    let done = wait_status(a, &id, &["succeeded", "failed"], Duration::from_secs(300));
    assert_eq!(done["status"], "succeeded", "{done}");
    let table = get(a, &format!("/jobs/{id}/summary")).json();
    table["rows"]
        .as_array()
        .unwrap_or_else(|| panic!("{table}"))
        .clone()
}

fn plate_scene(id: &str, name: &str, steps: usize) -> Value {
    let mut s = contact_core::scene::presets::get("plate-with-hole").unwrap();
    s["name"] = json!(name);
    s["domain"] = json!({"mesh": id});
    s["time"] = json!({"t_end": 1, "N": steps});
    s["output"]["every"] = json!(steps);
    s
}

#[test]
fn jobs_on_uploaded_meshes() {
    let dir = temp_dir("jobs");
    let srv = Server::start_with(Config {
        data_dir: dir.clone(),
        workers: 1,
        ..Config::default()
    });
    let a = srv.addr;
    let plate = test_mesh("plate-with-hole.msh");
    let a_id = upload(a, &plate).json()["id"].as_str().unwrap().to_string();
    let b_id = upload(a, &test_mesh("plate-with-hole-binary.msh")).json()["id"]
        .as_str()
        .unwrap()
        .to_string();
    let c_id = upload(a, &test_mesh("cylinder.msh")).json()["id"]
        .as_str()
        .unwrap()
        .to_string();
    let summary = get(a, &format!("/meshes/{a_id}")).json()["summary"].clone();
    let nodes = summary["nodes"].as_u64().unwrap() as usize;
    let cells = summary["cells"].as_u64().unwrap() as usize;

    // A job on the uploaded mesh, its parts bound to the mesh's groups.
    let scene = plate_scene(&a_id, "plate", 8);
    assert_eq!(
        scene["boundary"][1],
        json!({"type": "contact", "group": "contact"})
    );
    let r = post_json(a, "/jobs", &scene);
    assert_eq!(r.status, 202, "{}", r.text());
    let job = r.json()["id"].as_str().unwrap().to_string();
    let done = wait_status(a, &job, &["succeeded", "failed"], Duration::from_secs(120));
    assert_eq!(done["status"], "succeeded", "{done}");
    let f = get(a, &format!("/jobs/{job}/fields?step=last&mesh=1"));
    assert_eq!(f.status, 200, "{}", f.text());
    let f = f.json();
    assert_eq!(f["mesh"]["nodes"].as_array().unwrap().len(), nodes);
    assert_eq!(f["mesh"]["triangles"].as_array().unwrap().len(), cells);
    assert_eq!(f["u"].as_array().unwrap().len(), 2 * nodes);
    assert_eq!(f["zeta"].as_array().unwrap().len(), nodes);
    // The mesh's coordinates, as uploaded (node 0 of the file is the corner (0, 0)).
    assert_eq!(f["mesh"]["nodes"][0], json!([0.0, 0.0]));
    let vtu = get(a, &format!("/jobs/{job}/fields/last.vtu"));
    assert_eq!(vtu.status, 200);
    let text = vtu.text();
    let xml = roxmltree::Document::parse(&text).unwrap();
    let piece = xml.descendants().find(|n| n.has_tag_name("Piece")).unwrap();
    assert_eq!(
        piece.attribute("NumberOfPoints"),
        Some(nodes.to_string().as_str())
    );
    assert_eq!(
        piece.attribute("NumberOfCells"),
        Some(cells.to_string().as_str())
    );
    assert_eq!(get(a, &format!("/jobs/{job}/mesh")).status, 200);
    assert_eq!(get(a, &format!("/jobs/{job}/result.pvd")).status, 200);
    assert_eq!(get(a, &format!("/jobs/{job}/archive.tar")).status, 200);

    // The same scene on the same mesh id: answered from the store. The same geometry from
    // another file (the binary one, another id): a new job.
    let again = post_json(a, "/jobs", &scene);
    assert_eq!(again.status, 200, "{}", again.text());
    assert_eq!(again.json()["id"], job.as_str());
    let other = post_json(a, "/jobs", &plate_scene(&b_id, "plate", 8));
    assert_eq!(other.status, 202, "{}", other.text());
    let other_job = other.json()["id"].as_str().unwrap().to_string();
    assert_ne!(other_job, job);
    assert_ne!(other.json()["scene_hash"], again.json()["scene_hash"]);
    wait_status(a, &other_job, &["succeeded"], Duration::from_secs(120));

    // Meshes the service does not have: 422 at /domain/mesh, saying how to upload one.
    let unknown = "0".repeat(64);
    for (name, want) in [
        (
            unknown.clone(),
            format!("no uploaded mesh with id {unknown}; upload the .msh with POST /meshes"),
        ),
        (
            "../crates/contact-core/preset-meshes/plate-with-hole.msh".to_string(),
            "no uploaded mesh with id \"../crates/contact-core/preset-meshes/plate-with-hole.msh\"; upload the .msh with POST /meshes".to_string(),
        ),
        (
            "/etc/passwd".to_string(),
            "no uploaded mesh with id \"/etc/passwd\"; upload the .msh with POST /meshes".to_string(),
        ),
    ] {
        let p = assert_problem(&post_json(a, "/jobs", &plate_scene(&name, "x", 8)), 422);
        assert_eq!(p["errors"][0]["pointer"], "/domain/mesh", "{p}");
        let msg = p["errors"][0]["message"].as_str().unwrap();
        assert!(msg.starts_with(&want), "{msg}");
    }
    // A study of the uploaded mesh: its levels are red refinements; h is refused there.
    let study = json!({"study": {"scene": plate_scene(&a_id, "s", 8), "refine": [0, 1], "k": "1/8",
                                 "reference": {"refine": 2, "k": "1/8"}}});
    let rows = study_rows(a, &study);
    assert_eq!(rows.len(), 2);
    assert!(rows[1]["err_w"].as_f64().unwrap() < rows[0]["err_w"].as_f64().unwrap());
    let with_h = json!({"study": {"scene": plate_scene(&a_id, "s", 8), "h": "1/4", "k": ["1/4", "1/8"],
                                  "reference": {"h": "1/4", "k": "1/16"}}});
    let p = assert_problem(&post_json(a, "/jobs", &with_h), 422);
    assert!(p.to_string().contains("refine, not h"), "{p}");
    // A stored 3D mesh: scenes are 2D.
    // The plate's 2D scene on the tetrahedra of the cylinder: its 2-vectors are refused as
    // such.
    let p = assert_problem(&post_json(a, "/jobs", &plate_scene(&c_id, "x", 8)), 422);
    let errors = p["errors"].as_array().unwrap();
    assert!(
        errors
            .iter()
            .any(|e| e["pointer"] == "/boundary/2/f2"
                && e["message"].as_str().unwrap().contains("3D")),
        "{p}"
    );
    // A 3D job on the uploaded tetrahedra: fields with 3-vectors and tetrahedra, VTK_TETRA.
    let mut solid = contact_core::scene::presets::get("standing-cylinder").unwrap();
    solid["domain"] = json!({"mesh": c_id});
    solid["time"] = json!({"t_end": 1, "N": 2});
    let r = post_json(a, "/jobs", &solid);
    assert_eq!(r.status, 202, "{}", r.text());
    let solid_job = r.json()["id"].as_str().unwrap().to_string();
    let done = wait_status(
        a,
        &solid_job,
        &["succeeded", "failed"],
        Duration::from_secs(120),
    );
    assert_eq!(done["status"], "succeeded", "{done}");
    let f = get(a, &format!("/jobs/{solid_job}/fields?step=last&mesh=1")).json();
    let c_nodes = f["mesh"]["nodes"].as_array().unwrap().len();
    assert_eq!(f["mesh"]["dim"], 3);
    assert_eq!(f["mesh"]["nodes"][0].as_array().unwrap().len(), 3);
    assert_eq!(f["u"].as_array().unwrap().len(), 3 * c_nodes);
    let tets = f["mesh"]["tetrahedra"].as_array().unwrap().len();
    assert_eq!(f["sigma"].as_array().unwrap().len(), tets);
    assert_eq!(f["sigma"][0].as_array().unwrap().len(), 6);
    assert!(
        f["contact"][0]["tangential_velocity"].is_array(),
        "{}",
        f["contact"][0]
    );
    let vtu = get(a, &format!("/jobs/{solid_job}/fields/last.vtu")).text();
    assert!(vtu.contains(&format!("NumberOfCells=\"{tets}\"")));
    let summary = get(a, &format!("/jobs/{solid_job}/summary")).json();
    assert_eq!(summary["mesh"]["dim"], 3);
    assert_eq!(summary["mesh"]["tetrahedra"], tets);
    // A study of the uploaded tetrahedra: its levels are Bey refinements of the upload.
    let study = json!({"study": {"scene": solid, "refine": [0, 1], "k": "1/4",
                                 "reference": {"refine": 2, "k": "1/4"}}});
    let rows = study_rows(a, &study);
    assert_eq!(rows.len(), 2, "{rows:?}");
    for row in &rows {
        assert!(row["worst_residual"].as_f64().unwrap() <= 1e-10, "{row}");
    }
    assert!(
        rows[1]["err_w"].as_f64().unwrap() < rows[0]["err_w"].as_f64().unwrap(),
        "{rows:?}"
    );
    // Each Bey refinement multiplies the free velocity DOFs by about 8 (3 per new node).
    let unknowns: Vec<u64> = rows
        .iter()
        .map(|r| r["unknowns"].as_u64().unwrap())
        .collect();
    assert!(unknowns[1] > 5 * unknowns[0], "{unknowns:?}");
    // A bundled mesh is still known by its name.
    let mut bundled = plate_scene("plate-with-hole.msh", "bundled", 4);
    bundled["output"]["every"] = json!(4);
    let r = post_json(a, "/jobs", &bundled);
    assert_eq!(r.status, 202, "{}", r.text());
    let bundled_job = r.json()["id"].as_str().unwrap().to_string();
    wait_status(a, &bundled_job, &["succeeded"], Duration::from_secs(120));

    // A long job on mesh A runs; one on mesh B waits behind it (one worker).
    let running = post_json(a, "/jobs", &plate_scene(&a_id, "long", 50_000)).json()["id"]
        .as_str()
        .unwrap()
        .to_string();
    wait_status(a, &running, &["running"], Duration::from_secs(60));
    let queued = post_json(a, "/jobs", &plate_scene(&b_id, "waiting", 50_000)).json()["id"]
        .as_str()
        .unwrap()
        .to_string();
    assert_eq!(
        get(a, &format!("/jobs/{queued}")).json()["status"],
        "queued"
    );
    for (mesh, job, status) in [(&a_id, &running, "running"), (&b_id, &queued, "queued")] {
        let p = assert_problem(
            &http(a, "DELETE", &format!("/meshes/{mesh}"), &[], b""),
            409,
        );
        let detail = p["detail"].as_str().unwrap();
        assert!(
            detail.contains(job.as_str()) && detail.contains(status),
            "{detail}"
        );
        assert_eq!(get(a, &format!("/meshes/{mesh}")).status, 200);
    }
    // Once they are finished (cancelled here), the meshes can go.
    for job in [&queued, &running] {
        assert_eq!(
            http(a, "POST", &format!("/jobs/{job}/cancel"), &[], b"").status,
            202
        );
        wait_status(a, job, &["cancelled"], Duration::from_secs(60));
    }
    assert_eq!(
        http(a, "DELETE", &format!("/meshes/{a_id}"), &[], b"").status,
        204
    );
    // A job naming it now is refused; the finished job's summary stays, while the results
    // drawn on the mesh wait for the same file to be uploaded again.
    let p = assert_problem(&post_json(a, "/jobs", &scene), 422);
    assert_eq!(p["errors"][0]["pointer"], "/domain/mesh");
    assert_eq!(get(a, &format!("/jobs/{job}/summary")).status, 200);
    assert_eq!(get(a, &format!("/jobs/{job}/fields")).status, 200);
    for path in [
        "fields?mesh=1",
        "fields?step=0",
        "mesh",
        "fields/last.vtu",
        "result.pvd",
        "archive.tar",
    ] {
        let p = assert_problem(&get(a, &format!("/jobs/{job}/{path}")), 409);
        assert!(
            p["detail"]
                .as_str()
                .unwrap()
                .contains("upload the same .msh again"),
            "{path}: {p}"
        );
    }
    assert_eq!(upload(a, &plate).status, 201);
    assert_eq!(
        get(a, &format!("/jobs/{job}/fields?mesh=1")).json()["mesh"]["nodes"]
            .as_array()
            .unwrap()
            .len(),
        nodes
    );
    // ... and the scene is answered from the store again.
    assert_eq!(post_json(a, "/jobs", &scene).json()["id"], job.as_str());
    srv.stop();
    let _ = std::fs::remove_dir_all(&dir);
}
