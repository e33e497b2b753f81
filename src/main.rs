//! The `contact-sim` command line: a thin front end over the library. Each command's flags
//! and work are in `cli/`; this file parses and dispatches.

mod cli;

use clap::Parser;
use cli::Command;
use std::process::ExitCode;

fn main() -> ExitCode {
    map_large_blocks();
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

/// Blocks of 128 KiB and more (every vector, matrix and level of a run) are mapped for
/// themselves and given back to the system when freed. glibc's default raises this
/// threshold to the largest block freed so far (up to 32 MiB), after which such blocks
/// come from its heaps and arenas; the set-up's freed transients and each thread's arena
/// then stay resident beside the run. The gmsh part of `benches/part`, one thread: a
/// peak of 470 MB resident with the default, 422 MB with this
/// (docs/src/speed/speed.md#large-blocks-mapped-for-themselves).
fn map_large_blocks() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets glibc's allocation policy, here before any thread starts;
    // it takes no pointers.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 128 * 1024);
    }
}
