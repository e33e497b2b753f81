//! `cargo bench --bench speed`: the speed figures of the paper's convergence test
//! (h = k = 1/16 … 1/128; set CONTACT_SIM_BENCH_LEVELS=16,32,64,128,256 for more), with the
//! per-step time divided by one substitution with the velocity factor measured in the same run,
//! on one thread and on all cores;
//! then Tables 1 and 2 computed together against the reference run alone.

fn main() {
    let levels: Vec<usize> = std::env::var("CONTACT_SIM_BENCH_LEVELS")
        .unwrap_or_else(|_| "16,32,64,128".into())
        .split(',')
        .filter_map(|s| s.trim().parse().ok())
        .collect();
    let report = contact_core::harness::bench::run(
        contact_core::harness::bench::DEFAULT_PRESET,
        &levels,
        3,
        None,
        &[],
        &[1, contact_core::linalg::par::Threads::available()],
    )
    .expect("benchmark run");
    println!("{}", report.table());
    println!("{}", serde_json::to_string_pretty(&report).expect("JSON"));
    // Tables 1 and 2 together, one shared reference (target: under 4 s on 2 cores).
    let threads = contact_core::linalg::par::Threads::available();
    let tables = contact_core::harness::bench::tables(3, threads).expect("tables benchmark");
    println!("{}", serde_json::to_string_pretty(&tables).expect("JSON"));
}
