//! `contact-sim stress`: the stability suite, a table or JSON on stdout.

use super::{fail, pretty, progress};
use clap::{Args, ValueEnum};
use std::process::ExitCode;

#[derive(Args)]
pub struct StressArgs {
    /// The coarse subset (what tests/stability.rs runs).
    #[arg(long)]
    pub quick: bool,
    /// text (the table of README) or json (every figure of every case).
    #[arg(long, value_enum, default_value_t = StressFormat::Text)]
    pub format: StressFormat,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum StressFormat {
    Text,
    Json,
}

pub fn main(args: StressArgs) -> ExitCode {
    let bar = progress::bar(0, "cases");
    let report = contact_core::harness::stress::run_with(args.quick, |i, n, case| {
        bar.set_length(n as u64);
        bar.set_position(i as u64);
        bar.set_message(case.name.clone());
    });
    bar.finish_and_clear();
    match args.format {
        StressFormat::Json => outln!("{}", pretty(&report)),
        StressFormat::Text => out!("{}", report.text_table()),
    }
    if report.all_as_expected {
        ExitCode::SUCCESS
    } else {
        fail(1, "some stress cases did not do what they must (marked !)")
    }
}
