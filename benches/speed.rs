//! `cargo bench --bench speed`: the speed figures of the paper's convergence test
//! (h = k = 1/16 … 1/128; set CONTACT_SIM_BENCH_LEVELS=16,32,64,128,256 for more), with the
//! per-step time divided by one substitution with the velocity factor measured in the same run.

fn main() {
    let levels: Vec<usize> = std::env::var("CONTACT_SIM_BENCH_LEVELS")
        .unwrap_or_else(|_| "16,32,64,128".into())
        .split(',')
        .filter_map(|s| s.trim().parse().ok())
        .collect();
    let report = contact_sim::bench::run(&levels, 3).expect("benchmark run");
    println!("{}", report.table());
    println!("{}", serde_json::to_string_pretty(&report).expect("JSON"));
}
