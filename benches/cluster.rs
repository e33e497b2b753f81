//! `cargo bench --bench cluster`: throughput of a cluster on one PostgreSQL store — one
//! API-only node and 1, 2 or 3 worker processes (one worker thread each) on a throwaway
//! server from Debian's packages — in jobs per minute, for two job sizes:
//!
//! * small: paper-convergence at h = 1/8 over 40 steps (milliseconds of numerics: the
//!   figure is the queue's own overhead — submission, claim, lease, results, finish);
//! * medium: h = 1/32 over 400 steps (compute-bound).
//!
//! Each figure comes with the ratio to the ideal of the same run: `workers × 60 / t_job`,
//! where `t_job` is the same job computed in-process (no service) right before, capped at
//! the number of cores. Set CONTACT_SIM_CLUSTER_JOBS=small:N,medium:M to change the counts.

#[path = "../tests/service_support/mod.rs"]
mod service_support;

use service_support::postgres::*;
use service_support::{long_scene, TempDir};
use std::time::{Duration, Instant};

struct Size {
    name: &'static str,
    n: usize,
    steps: usize,
    jobs: usize,
}

fn main() {
    let mut sizes = vec![
        Size {
            name: "small",
            n: 8,
            steps: 40,
            jobs: 120,
        },
        Size {
            name: "medium",
            n: 32,
            steps: 400,
            jobs: 24,
        },
    ];
    if let Ok(spec) = std::env::var("CONTACT_SIM_CLUSTER_JOBS") {
        for part in spec.split(',') {
            if let Some((name, n)) = part.split_once(':') {
                if let (Some(s), Ok(n)) = (sizes.iter_mut().find(|s| s.name == name), n.parse()) {
                    s.jobs = n;
                }
            }
        }
    }
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let Some(pg) = Postgres::start("bench") else {
        eprintln!("PostgreSQL is not installed: nothing measured");
        return;
    };
    println!("size    jobs  workers  wall_s  jobs_per_min  t_job_s  ideal_per_min  ratio");
    for size in &sizes {
        // The job alone, in-process (fastest of three).
        let scene = long_scene("inproc", size.n, size.steps, 4);
        let t_job = (0..3)
            .map(|_| {
                let p = contact_core::scene::validate(&scene).expect("valid scene");
                let t = Instant::now();
                contact_core::run::run::<2>(p, Default::default(), |_, _| {
                    std::ops::ControlFlow::Continue(())
                })
                .expect("run");
                t.elapsed().as_secs_f64()
            })
            .fold(f64::INFINITY, f64::min);
        for workers in 1..=3 {
            let dir = TempDir::new("cluster-bench");
            let data = dir.0.join("shared");
            let url = pg.url();
            let api = api_node(&data, &url);
            let nodes: Vec<_> = (0..workers)
                .map(|i| {
                    let node = format!("b{workers}x{i}");
                    service_support::Proc::worker(&data, &node_args(&url, &node, "30"))
                })
                .collect();
            std::thread::sleep(Duration::from_millis(300));
            let t = Instant::now();
            let ids: Vec<String> = (0..size.jobs)
                .map(|j| {
                    let name = format!("{}-{workers}-{j}", size.name);
                    submit(api.addr, &long_scene(&name, size.n, size.steps, 4), &name)
                })
                .collect();
            let finals = wait_all(api.addr, &ids, Duration::from_secs(1800));
            let wall = t.elapsed().as_secs_f64();
            assert!(finals.iter().all(|f| f["status"] == "succeeded"));
            let per_min = size.jobs as f64 * 60.0 / wall;
            let ideal = workers.min(cores) as f64 * 60.0 / t_job;
            println!(
                "{:<7} {:>4}  {:>7}  {:>6.2}  {:>12.0}  {:>7.4}  {:>13.0}  {:>5.2}",
                size.name,
                size.jobs,
                workers,
                wall,
                per_min,
                t_job,
                ideal,
                per_min / ideal
            );
            drop(nodes);
            drop(api);
        }
    }
}
