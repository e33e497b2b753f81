//! A full disk loses no accepted work (docs/src/reference/disk-space.md), tested on a real
//! small file system: the data directory on a tmpfs mounted here, nearly filled, then grown
//! with `mount -o remount,size=…`. Needs root (CI runs as root); skipped only when not
//! root and CI is unset.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use contact_sim::disk::MinFreeDisk;
use contact_sim::Config;
use serde_json::json;

mod common;
use common::http::{get, post_json, wait_status};
use common::server::Server;

const MIB: u64 = 1 << 20;

/// A tmpfs mounted at a fresh directory, unmounted on drop.
struct Tmpfs(PathBuf);

impl Tmpfs {
    fn mount(bytes: u64) -> Tmpfs {
        let dir = std::env::temp_dir().join(format!("contact-sim-disk-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let ok = Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={bytes}"), "tmpfs"])
            .arg(&dir)
            .status()
            .is_ok_and(|s| s.success());
        assert!(ok, "mount -t tmpfs failed (root without CAP_SYS_ADMIN?)");
        Tmpfs(dir)
    }

    fn grow(&self, bytes: u64) {
        let ok = Command::new("mount")
            .args(["-o", &format!("remount,size={bytes}")])
            .arg(&self.0)
            .status()
            .is_ok_and(|s| s.success());
        assert!(ok, "remount failed");
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg("-l").arg(&self.0).status();
        let _ = std::fs::remove_dir(&self.0);
    }
}

fn is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
}

/// Leaves at most `free` bytes free on the file system of `dir` by writing the filler file
/// `name` there (nothing if less is free already).
fn fill_leaving(dir: &Path, name: &str, free: u64) {
    let now = contact_sim::disk::space(dir).unwrap().free;
    if now > free {
        std::fs::write(dir.join(name), vec![0u8; (now - free) as usize]).unwrap();
    }
}

/// Entries of `<data>/results` that are not the directory of one of `jobs`, and temporary
/// files anywhere under it.
fn strays(data: &Path, jobs: &[String]) -> Vec<String> {
    let mut out = Vec::new();
    let Ok(entries) = std::fs::read_dir(data.join("results")) else {
        return out;
    };
    for e in entries {
        let e = e.unwrap();
        let name = e.file_name().to_string_lossy().into_owned();
        if !jobs.contains(&name) {
            out.push(name.clone());
        }
        if e.path().is_dir() {
            for f in std::fs::read_dir(e.path()).unwrap() {
                let f = f.unwrap().file_name().to_string_lossy().into_owned();
                if f.starts_with(".tmp-") {
                    out.push(format!("{name}/{f}"));
                }
            }
        }
    }
    out
}

#[test]
fn a_full_disk_requeues_jobs_and_every_accepted_job_succeeds_once_it_grows() {
    if !is_root() {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI runs as root: this test must run there"
        );
        eprintln!("skipped: mounting a tmpfs needs root");
        return;
    }
    let fs = Tmpfs::mount(64 * MIB);
    let data = fs.0.join("data");
    let floor = 4 * MIB;
    let server = Server::start_with(Config {
        data_dir: data.clone(),
        workers: 2,
        lease_s: 2.0,
        min_free_disk: MinFreeDisk::Bytes(floor),
        ..Config::default()
    });
    let a = server.addr;

    // Just above the floor: submissions are accepted, but the jobs' results do not fit.
    fill_leaving(&fs.0, "filler", floor + 512 * 1024);
    let mut ids = Vec::new();
    for n in 30..34 {
        let r = post_json(
            a,
            "/jobs",
            &json!({"preset": "paper-exp2", "overrides": {"h": "1/16", "k": format!("1/{n}")}}),
        );
        assert_eq!(r.status, 202, "{}", r.text());
        ids.push(r.json()["id"].as_str().unwrap().to_string());
    }

    // A write finds the disk full: the node pauses (507, degraded), no job fails.
    let t = Instant::now();
    let health = loop {
        let h = get(a, "/healthz");
        if h.status == 503 {
            break h.json();
        }
        assert!(t.elapsed() < Duration::from_secs(300), "never degraded");
        std::thread::sleep(Duration::from_millis(20));
    };
    assert_eq!(health["type"], "/problems/degraded", "{health}");
    assert!(
        health["detail"].as_str().unwrap().contains("disk full"),
        "{health}"
    );
    let r = post_json(
        a,
        "/jobs",
        &json!({"preset": "paper-exp2", "overrides": {"h": "1/8"}}),
    );
    assert_eq!(r.status, 507, "{}", r.text());
    assert_eq!(r.json()["type"], "/problems/insufficient-storage");
    assert!(r.header("retry-after").is_some());
    let metrics = get(a, "/metrics").text();
    assert!(
        metrics.contains("contact_sim_disk_free_bytes "),
        "{metrics}"
    );
    assert!(
        metrics.contains(&format!("contact_sim_disk_min_free_bytes {floor}")),
        "{metrics}"
    );

    // Below the floor outright: 507 on both submissions, without any pause involved.
    fill_leaving(&fs.0, "filler-2", floor / 2);
    std::thread::sleep(Duration::from_millis(600));
    let r = post_json(
        a,
        "/jobs",
        &json!({"preset": "paper-exp2", "overrides": {"h": "1/8"}}),
    );
    assert_eq!(r.status, 507, "{}", r.text());
    let r = common::http::http(
        a,
        "POST",
        "/meshes",
        &[("Content-Type", "application/octet-stream")],
        b"$MeshFormat\n4.1 0 8\n$EndMeshFormat\n",
    );
    assert_eq!(r.status, 507, "{}", r.text());
    for id in &ids {
        let j = get(a, &format!("/jobs/{id}")).json();
        assert_ne!(j["status"], "failed", "{j}");
    }

    // The disk grows: every accepted job resumes and succeeds.
    fs.grow(512 * MIB);
    for id in &ids {
        let j = wait_status(
            a,
            id,
            &["succeeded", "failed", "cancelled"],
            Duration::from_secs(900),
        );
        assert_eq!(j["status"], "succeeded", "{j}");
    }
    assert_eq!(get(a, "/healthz").status, 200);
    assert_eq!(strays(&data, &ids), Vec::<String>::new());
    for id in &ids {
        assert!(data.join("results").join(id).join("summary.json").is_file());
        let r = common::http::http(a, "DELETE", &format!("/jobs/{id}"), &[], b"");
        assert_eq!(r.status, 204, "{}", r.text());
    }
    assert_eq!(strays(&data, &[]), Vec::<String>::new());
    server.stop();
}
