//! `contact-sim bench`: the speed figures of README.

use super::{fail, pretty};
use clap::Args;
use contact_core::harness::bench;
use contact_core::study;
use std::process::ExitCode;

#[derive(Args)]
pub struct BenchArgs {
    /// Levels 1/h = 1/k to run.
    #[arg(long, value_delimiter = ',', default_value = "16,32,64,128")]
    pub levels: Vec<usize>,
    /// The scene to run at each level (e.g. box-exp3 for the 3D figures).
    #[arg(long, default_value = bench::DEFAULT_PRESET)]
    pub preset: String,
    /// Repetitions per level (the fastest is reported).
    #[arg(long, default_value_t = 3)]
    pub repeat: usize,
    /// Linear solver path of every level, overriding the scene's `solver.linear`.
    #[arg(long = "linear-solver", value_parser = ["auto", "direct", "multigrid"])]
    pub linear_solver: Option<String>,
    /// Replace the scene's friction law by Tresca with each of these bounds g in turn (e.g.
    /// `2,20`: slipping and sticking runs of the same scene side by side, with their time
    /// ratio).
    #[arg(long = "friction-g", value_delimiter = ',')]
    pub friction_g: Vec<f64>,
    /// Thread counts to run every level with, in turn (e.g. `1,2`: the speed-up measured in
    /// one process). Default: all cores.
    #[arg(long, value_delimiter = ',', value_parser = clap::value_parser!(u64).range(1..=1024))]
    pub threads: Vec<u64>,
    /// Instead: Tables 1 and 2 together (one shared reference) against the reference
    /// run alone.
    #[arg(long)]
    pub tables: bool,
    /// Instead: the Schur complement onto the contact DOFs of the preset's velocity
    /// operator, by blocked solves and as the trailing block of the factor, at each level.
    #[arg(long)]
    pub schur: bool,
    /// Instead: fill nnz(L) and factor times of the preset's K_II ordered by AMD and by
    /// nested dissection, at each level.
    #[arg(long)]
    pub orderings: bool,
    /// Instead: adaptive against uniform refinement at equal true error on the l-bracket,
    /// the plate with a hole, paper-exp3 and paper-convergence (unknowns and times; the
    /// studies' tables on stderr).
    #[arg(long)]
    pub adapt: bool,
}

pub fn main(args: BenchArgs) -> ExitCode {
    let repeat = args.repeat.max(1);
    if args.tables {
        // The threads a study uses by default.
        let threads = study::Execution::default().threads;
        return match bench::tables(repeat, threads) {
            Ok(r) => {
                outln!("{}", pretty(&r));
                ExitCode::SUCCESS
            }
            Err(e) => fail(1, &e.to_string()),
        };
    }
    if args.adapt {
        let threads = args
            .threads
            .first()
            .map_or_else(contact_core::linalg::par::Threads::available, |&t| {
                t as usize
            });
        return match contact_core::harness::adaptivity::gains(threads) {
            Ok(g) => {
                for r in &g {
                    eprintln!("{}", r.table);
                }
                eprintln!("{}", contact_core::harness::adaptivity::table(&g));
                outln!("{}", pretty(&g));
                ExitCode::SUCCESS
            }
            Err(e) => fail(1, &e.to_string()),
        };
    }
    if args.orderings {
        return match bench::orderings(&args.preset, &args.levels, repeat) {
            Ok(r) => {
                outln!("{}", pretty(&r));
                ExitCode::SUCCESS
            }
            Err(e) => fail(1, &e.to_string()),
        };
    }
    if args.schur {
        return match bench::schur(&args.preset, &args.levels, repeat) {
            Ok(r) => {
                outln!("{}", pretty(&r));
                ExitCode::SUCCESS
            }
            Err(e) => fail(1, &e.to_string()),
        };
    }
    let linear = args
        .linear_solver
        .as_deref()
        .and_then(contact_core::linalg::LinearPath::parse);
    let threads: Vec<usize> = if args.threads.is_empty() {
        vec![contact_core::linalg::par::Threads::available()]
    } else {
        args.threads.iter().map(|&t| t as usize).collect()
    };
    match bench::run(
        &args.preset,
        &args.levels,
        repeat,
        linear,
        &args.friction_g,
        &threads,
    ) {
        Ok(report) => {
            eprintln!("{}", report.table());
            outln!("{}", pretty(&report));
            ExitCode::SUCCESS
        }
        Err(e) => fail(1, &e.to_string()),
    }
}
