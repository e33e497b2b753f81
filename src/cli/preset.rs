//! `contact-sim presets` and `contact-sim preset NAME`: the built-in scenes.

use super::{fail, pretty};
use clap::Args;
use contact_core::scene::presets;
use std::process::ExitCode;

#[derive(Args)]
pub struct PresetArgs {
    pub name: String,
}

/// `presets`: one line per preset, its name and what it shows.
pub fn list() -> ExitCode {
    for name in presets::names() {
        outln!("{name:20} {}", presets::description(name).unwrap_or(""));
    }
    ExitCode::SUCCESS
}

/// `preset NAME`: the preset as a complete scene file.
pub fn main(args: PresetArgs) -> ExitCode {
    match presets::get(&args.name) {
        Some(doc) => {
            outln!("{}", pretty(&doc));
            ExitCode::SUCCESS
        }
        None => fail(2, &unknown(&args.name)),
    }
}

/// The error for a preset name that does not exist, with the names that do.
pub fn unknown(name: &str) -> String {
    format!(
        "unknown preset {name:?}; known: {}",
        presets::names().join(", ")
    )
}
