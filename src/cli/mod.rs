//! Command-line interface: argument types and the dispatch to library calls. Each subcommand's
//! handler lives in its own module; this file only wires them together.

mod check_kernels;
pub mod demo;
mod devices;
pub mod eval;
pub mod extract;
pub mod inspect;
pub mod make_scene;
mod resume;
mod train;
mod train_surface;

use crate::backend::Backend;
use crate::gpu::{DeviceKind, Gpu, GpuOptions};
use crate::run::{RunDir, RunStage};
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
    /// renders, metrics.json and train_log.csv.
    Train(train::TrainArgs),
    /// Render a split of a trained run to PNG and print per-view and mean PSNR.
    Render(train::RenderArgs),
    /// Extract the level-set surfaces of a trained grid as a point cloud (binary PLY in Blender
    /// units with level, alpha and normals); for a stage-1 grid, the Plenoxels baseline σ = τ.
    Extract(extract::ExtractArgs),
    /// Chamfer distance, precision, recall and F1 of a point cloud against ground truth.
    Eval(eval::EvalArgs),
    /// Export a run's stage-1 grid as an svox2 `ckpt.npz`.
    Export(train::ExportArgs),
    /// Import an svox2 `ckpt.npz` as a stage-1 run directory (then `render`, or stage 2).
    Import(train::ImportArgs),
    /// Benchmarks: figures on the Vulkan device and the CPU twin, parity verdict, `--json` line.
    Bench(BenchArgs),
    /// The whole method on a built-in scene: make-scene → stage 1 → Plenoxels level-set sweep →
    /// stage 2 → extract → eval; prints the results table and writes report.md with PNG figures.
    Demo(demo::DemoArgs),
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
            ExitCode::FAILURE
        }
    }
}

/// Open the Vulkan device chosen by `--device` (validation on when `ALPHASURF_VALIDATION` is set).
fn open_gpu(cli: &Cli) -> anyhow::Result<Gpu> {
    Gpu::new(&GpuOptions {
        device: cli.device,
        validation: std::env::var_os("ALPHASURF_VALIDATION").is_some(),
        force_staging: false,
    })
}

/// The Vulkan device a training/rendering command should use, or `None` for the CPU backend.
/// `auto` takes the Vulkan device unless it is a CPU implementation (lavapipe) or missing.
fn backend_gpu<'a>(
    kind: Backend,
    cli: &Cli,
    slot: &'a mut Option<Gpu>,
) -> anyhow::Result<Option<&'a Gpu>> {
    match kind {
        Backend::Cpu => Ok(None),
        Backend::Vulkan => Ok(Some(slot.insert(open_gpu(cli)?))),
        Backend::Auto => match open_gpu(cli) {
            Ok(gpu) if gpu.info().kind != DeviceKind::Cpu => Ok(Some(slot.insert(gpu))),
            Ok(gpu) => {
                eprintln!(
                    "backend auto: {} is a CPU implementation of Vulkan; using the CPU backend, \
                     which is faster there (--backend vulkan forces the device)",
                    gpu.info().name
                );
                Ok(None)
            }
            Err(e) => {
                eprintln!("backend auto: no usable Vulkan device ({e:#}); using the CPU backend");
                Ok(None)
            }
        },
    }
}

fn exit(pass: bool) -> ExitCode {
    if pass {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}

/// Run `train`: the stage(s) asked for.
fn run_train(args: &train::TrainArgs, gpu: Option<&Gpu>) -> anyhow::Result<()> {
    train::check_stage_flags(args)?;
    match args.stage {
        train::Stage::Plenoxels => train::run_stage1(args, &train::load_data(args)?, gpu),
        train::Stage::Surface => train_surface::run(args, &train::load_data(args)?, gpu),
        train::Stage::All => run_all(args, gpu),
    }
}

/// `--stage all`: a parent run holding stage 1 in `plenoxels/` and stage 2 in `surface/`. With
/// `--resume` it continues whichever stage was interrupted: stage 1 (then stage 2 from scratch),
/// or stage 2 once stage 1 is done. Extending a finished stage 1 (`--iters`) under an existing
/// stage 2 is refused: that stage 2 was built on the old grid.
fn run_all(args: &train::TrainArgs, gpu: Option<&Gpu>) -> anyhow::Result<()> {
    let mut parent = RunDir::claim(
        &args.out,
        RunStage::All,
        train::open_mode(args),
        &[&args.data],
    )?;
    let data = train::load_data(args)?;
    parent.write_info(&train::run_info(args, None)?)?;
    let s1_dir = parent.file(crate::run::dir::ALL_STAGE1);
    let s2_dir = parent.file(crate::run::dir::ALL_STAGE2);
    let s1_ckpt = crate::train::stage1::checkpoint_path(&s1_dir);
    let s2_ckpt = crate::train::stage2::checkpoint_path(&s2_dir);
    let stage1_args = train::TrainArgs {
        stage: train::Stage::Plenoxels,
        out: s1_dir.clone(),
        resume: args.resume && s1_ckpt.exists(),
        overwrite: args.resume && !s1_ckpt.exists(),
        category: crate::train::Category::Thin,
        set: Vec::new(),
        alpha_init_scale: None,
        surface_iters: None,
        ..args.clone()
    };
    let stage2_args = train::TrainArgs {
        stage: train::Stage::Surface,
        out: s2_dir.clone(),
        init: Some(s1_dir.clone()),
        iters: args.surface_iters,
        res: None,
        resume: args.resume && s2_ckpt.exists(),
        overwrite: args.resume && !s2_ckpt.exists(),
        surface_iters: None,
        ..args.clone()
    };
    if args.resume && s2_ckpt.exists() {
        let s1 = crate::grid::checkpoint::load(&s1_ckpt)?;
        let step = s1.meta["step"].as_u64().unwrap_or(0);
        if args.iters.is_some_and(|n| n as u64 > step) {
            anyhow::bail!(
                "--resume --iters {}: stage 1 ({}) finished at step {step} and stage 2 ({}) was \
                 built on that grid; extending stage 1 would leave stage 2 stale. Extend stage 1 \
                 alone (train --stage plenoxels --resume --iters N --out {}), then restart stage \
                 2 (train --stage surface --init {} --out {} --overwrite)",
                args.iters.unwrap_or(0),
                s1_dir.display(),
                s2_dir.display(),
                s1_dir.display(),
                s1_dir.display(),
                s2_dir.display()
            );
        }
        eprintln!("--stage all --resume: stage 1 is done; resuming stage 2");
    } else {
        train::run_stage1(&stage1_args, &data, gpu)?;
    }
    train_surface::run(&stage2_args, &data, gpu)
}

fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    let mut gpu_used = None;
    let code = match &cli.command {
        Command::Devices => {
            devices::run()?;
            ExitCode::SUCCESS
        }
        Command::CheckKernels(args) => {
            let gpu = gpu_used.insert(open_gpu(&cli)?);
            exit(check_kernels::run(gpu, args)?)
        }
        Command::MakeScene(a) => {
            make_scene::run(a)?;
            ExitCode::SUCCESS
        }
        Command::Inspect(a) => {
            inspect::run(a)?;
            ExitCode::SUCCESS
        }
        Command::Train(a) => {
            let gpu = backend_gpu(a.backend, &cli, &mut gpu_used)?;
            run_train(a, gpu)?;
            ExitCode::SUCCESS
        }
        Command::Render(a) => {
            let gpu = backend_gpu(a.backend, &cli, &mut gpu_used)?;
            train::run_render(a, gpu)?;
            ExitCode::SUCCESS
        }
        Command::Extract(a) => {
            let gpu = backend_gpu(a.backend, &cli, &mut gpu_used)?;
            extract::run(a, gpu)?;
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
            demo::run(a, &cli)?;
            ExitCode::SUCCESS
        }
        Command::Bench(b) => match &b.kind {
            BenchKind::Plenoxels(args) => {
                let gpu = gpu_used.insert(open_gpu(&cli)?);
                crate::bench::plenoxels::run(gpu, args)?;
                ExitCode::SUCCESS
            }
            BenchKind::TimeVsError(args) => {
                crate::bench::time_vs_error::run(args, &cli)?;
                ExitCode::SUCCESS
            }
            BenchKind::Accuracy(args) => {
                crate::bench::accuracy::run(args, &cli)?;
                ExitCode::SUCCESS
            }
            BenchKind::Surface(args) => {
                let gpu = gpu_used.insert(open_gpu(&cli)?);
                crate::bench::surface::run(gpu, args)?;
                ExitCode::SUCCESS
            }
            BenchKind::Dda(args) => {
                let gpu = gpu_used.insert(open_gpu(&cli)?);
                exit(crate::bench::dda::run(gpu, args)?)
            }
            BenchKind::Cubic(args) => {
                let gpu = gpu_used.insert(open_gpu(&cli)?);
                exit(crate::bench::cubic::run(gpu, args)?)
            }
        },
    };
    if cli.profile {
        use std::io::Write;
        std::io::stdout().flush()?;
        match &gpu_used {
            Some(gpu) => eprint!("{}", gpu.profile().report()),
            None => eprintln!("profile: this command ran nothing on the Vulkan device"),
        }
    }
    Ok(code)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::{Category, Preset};

    fn train_args(extra: &[&str]) -> Result<train::TrainArgs, clap::Error> {
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
            (a.preset, a.category, a.backend),
            (Preset::Fast, Category::Thin, Backend::Auto)
        );
        let a =
            train_args(&["--preset", "paper", "--category", "dtu", "--backend", "cpu"]).unwrap();
        assert_eq!(
            (a.preset, a.category, a.backend),
            (Preset::Paper, Category::Dtu, Backend::Cpu)
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
}
