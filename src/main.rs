//! The `contact-sim` command line: a thin front end over the library. Each command's flags
//! and work are in `cli/`; this file parses and dispatches.

mod cli;

use clap::Parser;
use cli::Command;
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = cli::Cli::parse();
    cli::logging::init(cli.log_format);
    match cli.command.unwrap_or_default() {
        Command::Serve(args) => cli::serve::main(args),
        Command::Worker(args) => cli::worker::main(args),
        Command::Run(args) => cli::run::main(args),
        Command::Presets => cli::preset::list(),
        Command::Preset(args) => cli::preset::main(args),
        Command::Study(args) => cli::study::main(args),
        Command::Sweep(args) => cli::sweep::main(args),
        Command::Bench(args) => cli::bench::main(args),
        Command::Stress(args) => cli::stress::main(args),
        Command::Keys(args) => cli::keys::main(args),
    }
}
