//! Command-line interface: argument types and the dispatch to library calls. Each subcommand's
//! handler lives in its own module; this file only wires them together.

mod check_kernels;
mod demo;
mod devices;
mod eval;
mod extract;
mod inspect;
mod make_scene;
mod train;

use crate::pipeline::demo::DemoOptions;
use crate::pipeline::evaluate::EvaluateOptions;
use crate::pipeline::extract::ExtractOptions;
use crate::pipeline::render::RenderOptions;
use crate::pipeline::svox2::{ExportOptions, ImportOptions};
use crate::pipeline::{Devices, TrainOptions};
use crate::run::interrupt;
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
    /// List Vulkan devices (name, type, driver, memory, subgroup size, float atomics, limits) and
    /// the CPU backend.
    Devices,
    /// Run every GPU kernel against its CPU twin on random and adversarial inputs; one row per
    /// kernel; exit code 1 on any mismatch.
    CheckKernels(check_kernels::CheckKernelsArgs),
    /// Write a built-in procedural scene (NeRF-synthetic format + exact ground truth).
    MakeScene(make_scene::MakeSceneArgs),
    /// Summarise a NeRF-synthetic dataset: splits, cameras, object bounds, warnings.
    Inspect(inspect::InspectArgs),
    /// Train a reconstruction — stage 1 (Plenoxels), stage 2 (αSurf surfaces, `--init` from a
    /// stage-1 run) or both — with a progress bar, periodic atomic checkpoints (`--resume`), test
    /// renders, metrics.json and train_log.csv. Ctrl-C (or SIGTERM) checkpoints the step training
    /// is on and exits with 130 (143); a second one stops at once.
    Train(TrainOptions),
    /// Render a split of a trained run (stage 1: the density grid; stage 2: the surfaces) to PNG and
    /// print per-view and mean PSNR.
    Render(RenderOptions),
    /// Extract the level-set surfaces of a trained grid as a point cloud (binary PLY in Blender
    /// units with level, alpha and normals); for a stage-1 grid, the Plenoxels baseline σ = τ.
    Extract(ExtractOptions),
    /// Chamfer distance, precision, recall and F1 of a point cloud against ground truth.
    Eval(EvaluateOptions),
    /// Export a run's stage-1 grid as an svox2 `ckpt.npz`.
    Export(ExportOptions),
    /// Import an svox2 `ckpt.npz` as a stage-1 run directory (then `render`, or stage 2).
    Import(ImportOptions),
    /// Benchmarks: figures on the Vulkan device and the CPU twin, parity verdict, `--json` line.
    Bench(BenchArgs),
    /// The whole method on a built-in scene: make-scene → stage 1 → Plenoxels level-set sweep →
    /// stage 2 → extract → eval; prints the results table and writes report.md with PNG figures.
    Demo(DemoOptions),
}

/// `alphasurf bench <kind>`.
#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    #[command(subcommand)]
    pub kind: BenchKind,
}

/// Which benchmark.
#[derive(Subcommand, Debug)]
pub enum BenchKind {
    /// DDA cell walk: cells visited per second for random rays through a 256³ grid, and parity.
    Dda(crate::bench::dda::DdaBenchArgs),
    /// Cell cubic solver stress suite against an f64 oracle and the paper's Vieta baseline.
    Cubic(crate::bench::cubic::CubicBenchArgs),
    /// Stage-1 training throughput on both backends (rays/s, device time per kernel, samples
    /// per ray shaded/empty/skipped, atomic adds per ray) from the same partly trained grid.
    Plenoxels(crate::bench::plenoxels::PlenoxelsBenchArgs),
    /// Run time against error: stage 1 (and stage 2) over a sweep of backend × grid resolution ×
    /// steps on one built-in scene; wall time, training rays/s, Chamfer, F1 and test PSNR of the
    /// best Plenoxels level and of αSurf; CSV, a PNG plot, a table and `--json`.
    TimeVsError(crate::bench::time_vs_error::TimeVsErrorArgs),
    /// Stage-2 training throughput on both backends (rays/s, device time per kernel, cells, cubic
    /// solves, culled solves, hits, cut and guarded hits, atomic adds per ray) from the same grid,
    /// and the ratio to stage-1 training on the Vulkan device at the same resolution.
    Surface(crate::bench::surface::SurfaceBenchArgs),
    /// Accuracy on scenes with ground truth (the development set): per scene stage 1, the
    /// Plenoxels level sweep, stage 2, extract and eval; one table of αSurf against the scene's
    /// best level and the category's fixed level, with test PSNR; category means. Resumable.
    Accuracy(crate::bench::accuracy::AccuracyArgs),
}

/// Entry point of the binary: parse, run, map errors to a message and exit code 1.
pub fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            // A run a signal stopped exits as the signal would have (130 for Ctrl-C).
            interrupt::cause(&e).map_or(ExitCode::FAILURE, |i| {
                ExitCode::from(interrupt::exit_code(i))
            })
        }
    }
}

fn exit(pass: bool) -> ExitCode {
    if pass {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}

fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    let mut devices = Devices::new(cli.device);
    let code = match &cli.command {
        Command::Devices => {
            devices::run()?;
            ExitCode::SUCCESS
        }
        Command::CheckKernels(args) => exit(check_kernels::run(devices.gpu()?, args)?),
        Command::MakeScene(a) => {
            make_scene::run(a)?;
            ExitCode::SUCCESS
        }
        Command::Inspect(a) => {
            inspect::run(a)?;
            ExitCode::SUCCESS
        }
        Command::Train(a) => {
            train::run_train(a, devices.for_backend(a.backend)?)?;
            ExitCode::SUCCESS
        }
        Command::Render(a) => {
            train::run_render(a, devices.for_backend(a.backend)?)?;
            ExitCode::SUCCESS
        }
        Command::Extract(a) => {
            extract::run(a, devices.for_backend(a.backend)?)?;
            ExitCode::SUCCESS
        }
        Command::Eval(a) => {
            eval::run(a)?;
            ExitCode::SUCCESS
        }
        Command::Export(a) => {
            train::run_export(a)?;
            ExitCode::SUCCESS
        }
        Command::Import(a) => {
            train::run_import(a)?;
            ExitCode::SUCCESS
        }
        Command::Demo(a) => {
            demo::run(a, &mut devices)?;
            ExitCode::SUCCESS
        }
        Command::Bench(b) => match &b.kind {
            BenchKind::Plenoxels(args) => {
                crate::bench::plenoxels::run(devices.gpu()?, args)?;
                ExitCode::SUCCESS
            }
            BenchKind::TimeVsError(args) => {
                crate::bench::time_vs_error::run(args, &mut devices)?;
                ExitCode::SUCCESS
            }
            BenchKind::Accuracy(args) => {
                crate::bench::accuracy::run(args, &mut devices)?;
                ExitCode::SUCCESS
            }
            BenchKind::Surface(args) => {
                crate::bench::surface::run(devices.gpu()?, args)?;
                ExitCode::SUCCESS
            }
            BenchKind::Dda(args) => exit(crate::bench::dda::run(devices.gpu()?, args)?),
            BenchKind::Cubic(args) => exit(crate::bench::cubic::run(devices.gpu()?, args)?),
        },
    };
    if cli.profile {
        use std::io::Write;
        std::io::stdout().flush()?;
        match devices.opened() {
            Some(gpu) => eprint!("{}", gpu.profile().report()),
            None => eprintln!("profile: this command ran nothing on the Vulkan device"),
        }
    }
    Ok(code)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::Backend;
    use crate::train::{Category, Preset};

    fn train_args(extra: &[&str]) -> Result<TrainOptions, clap::Error> {
        let mut argv = vec!["alphasurf", "train", "--data", "d", "--out", "o"];
        argv.extend(extra);
        match Cli::try_parse_from(argv)?.command {
            Command::Train(a) => Ok(a),
            other => panic!("parsed as {other:?}"),
        }
    }

    #[test]
    fn typed_choices_keep_their_command_line_names() {
        let a = train_args(&[]).unwrap();
        assert_eq!(
            (a.preset(), a.category(), a.preset, a.category, a.backend),
            (Preset::Fast, Category::Thin, None, None, Backend::Auto)
        );
        let a =
            train_args(&["--preset", "paper", "--category", "dtu", "--backend", "cpu"]).unwrap();
        assert_eq!(
            (a.preset, a.category, a.backend),
            (Some(Preset::Paper), Some(Category::Dtu), Backend::Cpu)
        );
        for (flag, value) in [
            ("--category", "translucent"),
            ("--category", "synthetic"),
            ("--category", "real"),
            ("--backend", "vulkan"),
        ] {
            assert!(train_args(&[flag, value]).is_ok(), "{flag} {value}");
        }
        for (flag, value) in [
            ("--category", "shiny"),
            ("--preset", "imported"),
            ("--backend", "gpu"),
        ] {
            assert!(train_args(&[flag, value]).is_err(), "{flag} {value}");
        }
    }

    fn parse(argv: &[&str]) -> Command {
        let mut full = vec!["alphasurf"];
        full.extend(argv);
        Cli::try_parse_from(full).unwrap().command
    }

    /// The library's constructors with every flag at its default agree with the command line's
    /// defaults (the demo and the benchmarks build their options with them).
    #[test]
    fn library_defaults_are_the_command_line_defaults() {
        use crate::pipeline::train_options::Stage;
        let Command::Train(t) = parse(&["train", "--data", "d", "--out", "o"]) else {
            panic!("not train")
        };
        let lib = TrainOptions::new(Stage::Plenoxels, "d".into(), "o".into());
        assert_eq!(format!("{t:?}"), format!("{lib:?}"));
        let Command::Extract(e) = parse(&["extract", "--run", "r", "--out", "p.ply"]) else {
            panic!("not extract")
        };
        let lib = ExtractOptions::for_run("r".into(), "p.ply".into());
        assert_eq!(format!("{e:?}"), format!("{lib:?}"));
        let Command::Eval(e) = parse(&["eval", "--pred", "p.ply", "--gt", "g.ply"]) else {
            panic!("not eval")
        };
        let lib = EvaluateOptions::new("p.ply".into(), "g.ply".into());
        assert_eq!(format!("{e:?}"), format!("{lib:?}"));
    }
}
