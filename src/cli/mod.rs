//! Command-line interface: argument types and the dispatch to library calls. Each subcommand's
//! handler lives in its own module; this file only wires them together.

pub mod inspect;
pub mod make_scene;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// alphasurf — surface reconstruction for thin and semi-transparent objects (αSurf on Plenoxels),
/// with Vulkan compute kernels and a CPU twin for each.
#[derive(Parser, Debug)]
#[command(name = "alphasurf", version, about, long_about = None)]
pub struct Cli {
    /// Vulkan device index from `alphasurf devices` (default: first discrete or integrated GPU,
    /// else lavapipe).
    #[arg(long, global = true, env = "ALPHASURF_DEVICE")]
    pub device: Option<usize>,
    /// Print per-kernel device times (Vulkan timestamp queries) when the command ends.
    #[arg(long, global = true)]
    pub profile: bool,
    #[command(subcommand)]
    pub command: Command,
}

/// Subcommands.
#[derive(Subcommand, Debug)]
pub enum Command {
    /// Write a built-in procedural scene (NeRF-synthetic format + exact ground truth).
    MakeScene(make_scene::MakeSceneArgs),
    /// Summarise a NeRF-synthetic dataset: splits, cameras, object bounds, warnings.
    Inspect(inspect::InspectArgs),
}

/// Entry point of the binary: parse, run, map errors to a message and exit code 1.
pub fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    match cli.command {
        Command::MakeScene(a) => make_scene::run(&a)?,
        Command::Inspect(a) => inspect::run(&a)?,
    }
    Ok(ExitCode::SUCCESS)
}
