//! `alphasurf train` and `alphasurf render`: wire the dataset, a backend and the trainer.

use super::resume::resume;
use crate::backend::Backend;
use crate::data::{dataset::peak_rss_bytes, Dataset, LoadOptions};
use crate::gpu::Gpu;
use crate::grid::Grid;
use crate::plenoxel::{CpuPlenoxels, Plenoxels, VulkanPlenoxels};
use crate::run::{self, read_info, Open, RunDir, RunInfo, RunStage};
use crate::train::{render_split, stage1, Category, Preset, Stage1Config};
use anyhow::{bail, Context, Result};
use serde_json::json;
use std::path::PathBuf;
use std::time::Instant;

/// Which stage to train.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// Stage 1: Plenoxels density + SH grid (writes plenoxels.npz).
    Plenoxels,
    /// Stage 2: αSurf surfaces initialised from a stage-1 grid (`--init`; writes surface.npz).
    Surface,
    /// Stage 1 into OUT/plenoxels, then stage 2 from it into OUT/surface.
    All,
}

/// Arguments of `train`.
#[derive(clap::Args, Debug, Clone)]
pub struct TrainArgs {
    /// Which stage.
    #[arg(long, value_enum, default_value = "plenoxels")]
    pub stage: Stage,
    /// Dataset directory (NeRF-synthetic format, e.g. from `make-scene`).
    #[arg(long)]
    pub data: PathBuf,
    /// Stage 2: the stage-1 run directory (its plenoxels.npz) or an svox2 `ckpt.npz` to
    /// initialise from (required unless resuming).
    #[arg(long)]
    pub init: Option<PathBuf>,
    /// Stage 2: the data category whose hyper-parameters from the paper's supplement apply
    /// (levels, learning rates, regulariser weights, truncation schedule).
    #[arg(long, value_enum, default_value_t = Category::Thin)]
    pub category: Category,
    /// Stage 2: initial raw opacity σα = s·σ, s > 0. Default: preset `paper` 0.005 (the released
    /// code); preset `fast` 0.05 for thin, 0.01 for translucent, 0.005 otherwise, and at least
    /// 0.005·(N/128)^1.5 on a stage-1 grid of N³: its short schedule cannot raise σα far enough
    /// on a fine grid before truncation leaves each ray two hits.
    #[arg(long)]
    pub alpha_init_scale: Option<f32>,
    /// Stage 2 steps (overrides the preset; with `--stage all`, `--iters` is stage 1's).
    #[arg(long)]
    pub surface_iters: Option<u32>,
    /// Stage 2: override any field of the configuration (as printed in metrics.json), e.g.
    /// `--set lambda_h=1e-3 --set lr_delta.init=1e-4`; the value is JSON. Repeatable.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Run directory: checkpoints, test renders, metrics.json.
    #[arg(long)]
    pub out: PathBuf,
    /// The schedule of both stages.
    #[arg(long, value_enum, default_value_t = Preset::Fast)]
    pub preset: Preset,
    /// Where the kernels run.
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    pub backend: Backend,
    /// Number of steps (overrides the preset; stage 1's learning-rate decays keep their length,
    /// stage 2's schedules scale with it).
    #[arg(long)]
    pub iters: Option<u32>,
    /// Final grid resolution (the preset's upsampling schedule is scaled to it).
    #[arg(long)]
    pub res: Option<u32>,
    /// Rays per batch (overrides the preset).
    #[arg(long)]
    pub batch: Option<u32>,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Box-downscale the images by this factor.
    #[arg(long, default_value_t = 1)]
    pub downscale: u32,
    /// Write a checkpoint every N steps (overrides the preset).
    #[arg(long)]
    pub checkpoint_every: Option<u32>,
    /// Continue from the run directory's checkpoint (its configuration wins).
    #[arg(long, conflicts_with = "overwrite")]
    pub resume: bool,
    /// Replace the run already in `--out` (only a run: a folder that is not one is never
    /// overwritten).
    #[arg(long)]
    pub overwrite: bool,
    /// Hide the progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// Arguments of `render`.
#[derive(clap::Args, Debug)]
pub struct RenderArgs {
    /// A run directory written by `train`.
    #[arg(long)]
    pub run: PathBuf,
    /// Which split: train, val or test.
    #[arg(long, default_value = "test")]
    pub split: String,
    /// Output directory for the PNGs.
    #[arg(long)]
    pub out: PathBuf,
    /// Dataset directory (default: the one the run was trained on).
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Where the kernels run.
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    pub backend: Backend,
}

/// The Vulkan backend on `gpu`, or the CPU backend when there is none (see `cli::backend_gpu`).
fn make_backend(gpu: Option<&Gpu>, grid: Grid) -> Result<Box<dyn Plenoxels>> {
    Ok(match gpu {
        Some(gpu) => Box::new(VulkanPlenoxels::new(gpu, grid)?),
        None => Box::new(CpuPlenoxels::new(grid)),
    })
}

fn config(args: &TrainArgs) -> Result<Stage1Config> {
    let mut cfg = Stage1Config::preset(args.preset)?;
    cfg.seed = args.seed;
    if let Some(n) = args.iters {
        if n == 0 {
            bail!("--iters must be at least 1");
        }
        cfg.upsample
            .iter_mut()
            .for_each(|u| u.0 = (u.0 as u64 * n as u64 / cfg.iters as u64) as u32);
        cfg.checkpoint_every = cfg.checkpoint_every.min(n);
        cfg.iters = n;
    }
    if let Some(r) = args.res {
        if !(8..=1024).contains(&r) {
            bail!("--res {r}: expected 8 ..= 1024");
        }
        let last = cfg.upsample.last().map_or(cfg.res, |u| u.1);
        cfg.res = (cfg.res as u64 * r as u64 / last as u64).max(8) as u32;
        cfg.upsample
            .iter_mut()
            .for_each(|u| u.1 = (u.1 as u64 * r as u64 / last as u64) as u32);
    }
    if let Some(c) = args.checkpoint_every {
        if c == 0 {
            bail!("--checkpoint-every must be at least 1");
        }
        cfg.checkpoint_every = c;
    }
    if let Some(b) = args.batch {
        if b == 0 {
            bail!("--batch must be at least 1");
        }
        cfg.batch = b;
    }
    Ok(cfg)
}

/// How `args` open their run directory.
pub(super) fn open_mode(args: &TrainArgs) -> Open {
    match (args.resume, args.overwrite) {
        (true, _) => Open::Resume,
        (false, true) => Open::Overwrite,
        (false, false) => Open::Fresh,
    }
}

/// Refuse flags the stage asked for would ignore.
pub(super) fn check_stage_flags(args: &TrainArgs) -> Result<()> {
    let mut ignored = Vec::new();
    if args.stage == Stage::Plenoxels {
        let stage2_only = [
            ("--init", args.init.is_some()),
            ("--category", args.category != Category::Thin),
            ("--set", !args.set.is_empty()),
            ("--alpha-init-scale", args.alpha_init_scale.is_some()),
            ("--surface-iters", args.surface_iters.is_some()),
        ];
        ignored.extend(stage2_only.iter().filter(|f| f.1).map(|f| f.0));
    }
    if args.stage == Stage::Surface && args.res.is_some() {
        ignored.push("--res");
    }
    if args.stage == Stage::All && args.init.is_some() {
        ignored.push("--init");
    }
    if !ignored.is_empty() {
        bail!(
            "{} {} not used by --stage {} ({}); leave {} out",
            ignored.join(", "),
            if ignored.len() == 1 { "is" } else { "are" },
            match args.stage {
                Stage::Plenoxels => "plenoxels",
                Stage::Surface => "surface",
                Stage::All => "all",
            },
            match args.stage {
                Stage::Plenoxels => "they configure stage 2",
                Stage::Surface => "the grid resolution comes from --init",
                Stage::All => "stage 2 starts from this run's own stage 1",
            },
            if ignored.len() == 1 { "it" } else { "them" }
        );
    }
    for (name, v) in [
        ("--iters", args.iters),
        ("--surface-iters", args.surface_iters),
    ] {
        if v == Some(0) {
            bail!("{name} must be at least 1");
        }
    }
    if let Some(b) = args.batch {
        check_batch_memory(b)?;
    }
    Ok(())
}

/// Bytes a training step holds per ray of its batch: the sampled batch, its flat copies handed
/// to the backend and the backend's per-ray buffers. Peak RSS grows by about 100 B per ray on the
/// CPU backend (stage 1, `--batch` 2000 against 400000); the Vulkan backend also stages its
/// copies, hence the margin.
const BYTES_PER_BATCH_RAY: f64 = 256.0;

/// Refuse a `--batch` whose per-step buffers cannot fit in the memory available.
fn check_batch_memory(batch: u32) -> Result<()> {
    crate::run::memory::ensure_fits(
        &format!("--batch {batch}"),
        batch as f64 * BYTES_PER_BATCH_RAY,
    )
}

/// Run stage 1.
pub(super) fn run_stage1(args: &TrainArgs, data: &Loaded, gpu: Option<&Gpu>) -> Result<()> {
    let t_all = Instant::now();
    // A new run's flags are checked before its folder is claimed.
    let fresh_cfg = if args.resume {
        None
    } else {
        Some(config(args)?)
    };
    let mut run = RunDir::claim(
        &args.out,
        RunStage::Plenoxels,
        open_mode(args),
        &[&args.data],
    )?;
    let (load_s, data) = (data.seconds, &data.data);
    let ckpt = stage1::checkpoint_path(&args.out);
    let (mut backend, cfg, start) = if let Some(cfg) = fresh_cfg {
        let grid = Grid::sphere(
            cfg.res,
            data.scene.centre.to_array(),
            [data.scene.radius; 3],
            1.0,
            cfg.init_sigma,
        );
        (make_backend(gpu, grid)?, cfg, 0)
    } else {
        let restore = || {
            let probe = crate::grid::checkpoint::load(&ckpt)?;
            let mut b = make_backend(gpu, probe.grid)?;
            let (step, cfg) = stage1::resume(b.as_mut(), &ckpt)?;
            check_resume_flags(args, &cfg)?;
            Ok((b, step, cfg))
        };
        match resume(
            &ckpt,
            args.iters,
            |c: &mut Stage1Config| &mut c.iters,
            restore,
        )? {
            Some(resumed) => resumed,
            None => return Ok(()),
        }
    };
    run.write_info(&run_info(args, None)?)?;
    eprintln!(
        "stage 1 on {} ({}): preset {}, {} steps of {} rays, grid {}³{}",
        backend.name(),
        gpu.map_or("rayon".to_string(), |g| g.info().name.clone()),
        cfg.preset,
        cfg.iters,
        cfg.batch,
        cfg.res,
        cfg.upsample
            .iter()
            .map(|(s, r)| format!(" → {r}³ at step {s}"))
            .collect::<String>()
    );
    let (report, rendered) =
        stage1::train(backend.as_mut(), data, &cfg, &args.out, start, !args.quiet)?;
    for (i, p) in rendered.psnr.iter().enumerate() {
        println!("test view {i:>3}: PSNR {p:.2} dB");
    }
    let spr = report.samples_per_ray;
    println!(
        "per training ray: {:.1} samples shaded, {:.1} evaluated empty, {:.1} skipped by the occupancy volume; {:.1} gradient atomic adds",
        spr[0], spr[1], spr[2], spr[3]
    );
    println!(
        "stage 1 done: test PSNR {:.2} dB, {:.0} training rays/s, {} vertices ({:.0} B each with optimiser state), {:.1} s",
        report.test_psnr,
        report.train_rays_per_s,
        report.allocated_vertices,
        report.bytes_per_vertex,
        load_s + t_all.elapsed().as_secs_f64()
    );
    let metrics = json!({
        "stage": "plenoxels",
        "backend": backend.name(),
        "device": gpu.map(|g| g.info().name.clone()),
        "wall_seconds": {
            "load": load_s,
            "train": report.train_seconds,
            "upsample": report.upsample_seconds,
            "checkpoint": report.checkpoint_seconds,
            "render_test": report.render_seconds,
            "total": load_s + t_all.elapsed().as_secs_f64(),
        },
        "train_rays_per_s": report.train_rays_per_s,
        "final_train_mse": report.final_mse,
        "test_psnr": report.test_psnr,
        "test_psnr_per_view": rendered.psnr,
        "samples_per_ray": { "shaded": report.samples_per_ray[0], "empty": report.samples_per_ray[1], "skipped": report.samples_per_ray[2] },
        "atomic_adds_per_ray": report.samples_per_ray[3],
        "allocated_vertices": report.allocated_vertices,
        "bytes_per_vertex": report.bytes_per_vertex,
        "peak_rss_bytes": peak_rss_bytes(),
        "config": cfg,
    });
    run.write_metrics(&metrics)
}

/// On `--resume` the checkpoint's configuration wins: a flag that asks for something else is an
/// error rather than silently ignored.
fn check_resume_flags(args: &TrainArgs, cfg: &Stage1Config) -> Result<()> {
    let final_res = cfg.upsample.last().map_or(cfg.res, |u| u.1);
    let clashes = [
        ("--res", args.res.is_some_and(|r| r != final_res)),
        ("--batch", args.batch.is_some_and(|b| b != cfg.batch)),
        (
            "--preset",
            args.preset != Preset::Fast && args.preset != cfg.preset,
        ),
    ];
    let named: Vec<&str> = clashes.iter().filter(|c| c.1).map(|c| c.0).collect();
    if !named.is_empty() {
        bail!(
            "--resume continues the checkpoint's configuration (grid {final_res}³, batch {}, \
             preset {}); {} cannot change it (only --iters can)",
            cfg.batch,
            cfg.preset,
            named.join(", ")
        );
    }
    Ok(())
}

/// A dataset loaded for training, and the seconds its loading took.
pub(super) struct Loaded {
    pub data: Dataset,
    pub seconds: f64,
}

/// The dataset `--data` names, at `--downscale`; `inspect`'s warnings are repeated on stderr.
pub(super) fn load_data(args: &TrainArgs) -> Result<Loaded> {
    let t = Instant::now();
    let data = Dataset::load(
        &args.data,
        &LoadOptions {
            downscale: args.downscale,
            ..Default::default()
        },
    )?;
    for w in crate::data::inspect::inspect(&data).warnings {
        eprintln!("warning: {}: {w}", args.data.display());
    }
    Ok(Loaded {
        data,
        seconds: t.elapsed().as_secs_f64(),
    })
}

/// The `run.json` of a training run: the dataset's absolute path, the downscale factor and
/// (stage 2) the grid it started from.
pub(super) fn run_info(args: &TrainArgs, init: Option<PathBuf>) -> Result<RunInfo> {
    Ok(RunInfo {
        stage: None,
        data: std::fs::canonicalize(&args.data)
            .with_context(|| format!("dataset {}", args.data.display()))?,
        downscale: args.downscale,
        init,
        imported_from: None,
    })
}

/// Run `render`.
pub fn run_render(args: &RenderArgs, gpu: Option<&Gpu>) -> Result<()> {
    let ckpt_path = run::dir::stage1_checkpoint(&args.run, "render")?;
    let data_dir = match &args.data {
        Some(d) => d.clone(),
        None => read_info(&args.run).context("(or pass --data)")?.data,
    };
    run::outputs::check_output_dir(&args.out, &[&ckpt_path, &data_dir])?;
    let data = Dataset::load(&data_dir, &LoadOptions::default())?;
    let split = match args.split.as_str() {
        "train" => &data.train,
        "val" => data.val(),
        "test" => &data.test,
        s => bail!("--split {s}: expected train, val or test"),
    };
    let ckpt = crate::grid::checkpoint::load(&ckpt_path)?;
    let stop = serde_json::from_value::<Stage1Config>(ckpt.meta["config"].clone())
        .map(|c| c.stop_thresh)
        .unwrap_or(1e-7);
    let mut backend = make_backend(gpu, ckpt.grid)?;
    let r = render_split(backend.as_mut(), &data, split, stop, &args.out)?;
    for (i, p) in r.psnr.iter().enumerate() {
        println!("{} view {i:>3}: PSNR {p:.2} dB", r.split);
    }
    println!(
        "mean PSNR {:.2} dB over {} views -> {}",
        r.mean_psnr,
        r.psnr.len(),
        args.out.display()
    );
    Ok(())
}

/// Arguments of `export`.
#[derive(clap::Args, Debug)]
pub struct ExportArgs {
    /// A run directory written by `train` (or `import`).
    #[arg(long)]
    pub run: PathBuf,
    /// Output svox2 checkpoint (`ckpt.npz`: links, density_data, sh_data, radius, center).
    #[arg(long)]
    pub out: PathBuf,
}

/// Arguments of `import`.
#[derive(clap::Args, Debug)]
pub struct ImportArgs {
    /// An svox2 `ckpt.npz` (float16 or float32 data).
    #[arg(long)]
    pub ckpt: PathBuf,
    /// The dataset it was trained on (recorded for `render`).
    #[arg(long)]
    pub data: PathBuf,
    /// Run directory to create.
    #[arg(long)]
    pub out: PathBuf,
    /// Replace the run already in `--out` (only a run: a folder that is not one is never
    /// overwritten).
    #[arg(long)]
    pub overwrite: bool,
}

/// Run `export`: the run's stage-1 grid as an svox2 checkpoint (written atomically).
pub fn run_export(args: &ExportArgs) -> Result<()> {
    let ckpt_path = run::dir::stage1_checkpoint(&args.run, "export")?;
    run::outputs::check_output_file(&args.out, &[&ckpt_path])?;
    let ck = crate::grid::checkpoint::load(&ckpt_path)?;
    crate::grid::npz::save_svox2(&ck.grid, &args.out)?;
    println!(
        "exported {}³ grid ({} vertices) to {}",
        ck.grid.res[0],
        ck.grid.allocated(),
        args.out.display()
    );
    Ok(())
}

/// Run `import`: an svox2 checkpoint becomes a finished stage-1 run directory.
pub fn run_import(args: &ImportArgs) -> Result<()> {
    let grid = crate::grid::npz::load_svox2(&args.ckpt)?;
    let data = std::fs::canonicalize(&args.data)
        .with_context(|| format!("dataset {}", args.data.display()))?;
    let open = if args.overwrite {
        Open::Overwrite
    } else {
        Open::Fresh
    };
    let mut run = RunDir::claim(&args.out, RunStage::Plenoxels, open, &[&args.ckpt, &data])?;
    let mut cfg = Stage1Config::paper();
    cfg.preset = Preset::Imported;
    cfg.res = grid.res[0];
    cfg.upsample.clear();
    cfg.iters = 0;
    let meta =
        json!({ "stage": "plenoxels", "step": 0, "config": cfg, "imported_from": args.ckpt });
    let n = grid.allocated();
    crate::grid::checkpoint::save(
        &run.file(run::dir::STAGE1_CHECKPOINT),
        &grid,
        &[
            ("rms_density", &vec![0.0; n]),
            ("rms_sh", &vec![0.0; n * crate::grid::SH_DIM]),
        ],
        &meta,
    )?;
    run.write_info(&RunInfo {
        stage: None,
        data,
        downscale: 1,
        init: None,
        imported_from: Some(args.ckpt.clone()),
    })?;
    println!(
        "imported {} ({:?} grid, {n} vertices) into {}",
        args.ckpt.display(),
        grid.res,
        args.out.display()
    );
    Ok(())
}
