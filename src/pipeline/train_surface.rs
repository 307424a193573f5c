//! Stage 2 (αSurf) as a library call: initialise the surface grid from a stage-1 run or an
//! svox2 checkpoint (method.md §3.1), or resume a stage-2 run, train it, and write
//! `metrics.json` ([`SurfaceMetrics`]).

use super::metrics::{SurfaceFigures, SurfaceMetrics, SurfacePerRay};
use super::train_options::TrainOptions;
use super::train_run::{claim, refuse_clashes, resume, run_info, Loaded, Trained, Trainer};
use crate::checkpoint::format as checkpoint;
use crate::checkpoint::{Backdrop, BackgroundRecord};
use crate::data::BackgroundMode;
use crate::data::Dataset;
use crate::gpu::Gpu;
use crate::grid::surface::SurfaceGrid;
use crate::grid::{npz, Grid};
use crate::run::same_data::check_same_data;
use crate::run::{self, RunStage};
use crate::surface::{CpuSurface, SurfaceBackend, SurfaceStage, VulkanSurface};
use crate::train::{surface_steps, SurfaceConfig};
use anyhow::{Context, Result};
use std::path::Path;
use std::time::Instant;

/// The Vulkan backend on `gpu`, or the CPU backend when there is none.
pub(super) fn make_backend(
    gpu: Option<&Gpu>,
    grid: SurfaceGrid,
) -> Result<Box<dyn SurfaceBackend>> {
    Ok(match gpu {
        Some(gpu) => {
            grid.validate()?;
            Box::new(VulkanSurface::new(gpu, grid)?)
        }
        None => Box::new(CpuSurface::new(grid)?),
    })
}

/// The stage-1 grid `--init` names (a run directory: its plenoxels.npz, or an npz file) and the
/// background it trained with (an svox2 `ckpt.npz`: white), with its spheres (kept, not
/// learned). A stage-1 run must have been trained on `data` (unless `--allow-other-data`); one
/// that stopped before its last step is named.
fn load_init(opts: &TrainOptions, path: &Path, data: &Dataset) -> Result<(Grid, Backdrop)> {
    let file = if path.is_dir() {
        let ck = run::dir::plenoxels_checkpoint(path, "--init")?;
        if run::files::is_run(path) {
            let recorded = run::read_info(path)?;
            let now = run_info(opts, data, None)?;
            check_same_data("--init", path, &recorded, &now, opts.allow_other_data)?;
        }
        ck
    } else {
        path.to_path_buf()
    };
    let grid = npz::load_svox2(&file).with_context(|| format!("--init {}", path.display()))?;
    let meta = checkpoint::read_meta(&file)?;
    if let Some(meta) = &meta {
        let step = meta["step"].as_u64();
        let iters = meta["config"]["iters"].as_u64();
        if let (Some(step), Some(iters)) = (step, iters) {
            if step < iters {
                eprintln!(
                    "warning: --init {}: stage 1 stopped at step {step} of {iters} (interrupted); \
                     stage 2 starts from that grid (to finish stage 1 first: train --stage \
                     plenoxels --resume --out {})",
                    path.display(),
                    path.display()
                );
            }
        }
    }
    let bg = match &meta {
        Some(meta) => BackgroundRecord::from_meta(meta, &file)?,
        None => BackgroundRecord::start(BackgroundMode::White),
    };
    let spheres = bg.read_spheres(&file, false)?;
    Ok((
        grid,
        Backdrop {
            record: bg,
            spheres,
        },
    ))
}

/// A new stage-2 grid, its configuration and its background (stage 1's, carried on) from
/// `--init` and the flags.
fn fresh_start(
    opts: &TrainOptions,
    data: &Dataset,
) -> Result<(SurfaceGrid, SurfaceConfig, Backdrop)> {
    let init = opts
        .init
        .as_ref()
        .context("stage 2 needs --init STAGE1_RUN_DIR or --init ckpt.npz")?;
    let (density, bg) = load_init(opts, init, data)?;
    // `auto` resolved for the data (for a stage-1 run directory: that run's mode).
    bg.record
        .ensure_mode(data.background, &format!("--init {}", init.display()))?;
    let cfg = opts.surface_config(density.res.into_iter().max().unwrap_or(0))?;
    opts.check_surface_memory(&cfg)?;
    let grid = SurfaceGrid::from_density(&density, &cfg.init)
        .with_context(|| format!("initialising the surfaces from {}", init.display()))?;
    eprintln!(
        "initialised from {}: {}³ grid, {} of {} vertices kept (σ > {}, dilated twice), \
         mean |∇σ| {:.4}, levels τ = {:?}, σα = {}·σ",
        init.display(),
        grid.res[0],
        grid.delta.len(),
        density.allocated(),
        cfg.init.density_levels[0] / 2.0,
        grid.gradient_scale,
        grid.levels,
        cfg.init.alpha_init_scale
    );
    Ok((grid, cfg, bg))
}

/// Train stage 2 into `opts.out` on `gpu` (`None`: the CPU twins).
pub fn train_surface(
    opts: &TrainOptions,
    data: &Loaded,
    gpu: Option<&Gpu>,
) -> Result<Trained<SurfaceMetrics>> {
    let timing = (data.seconds, Instant::now());
    // A new run's inputs and flags are checked before its folder is claimed.
    let fresh = (!opts.resume)
        .then(|| fresh_start(opts, &data.data))
        .transpose()?;
    let mut inputs = vec![opts.data.as_path()];
    inputs.extend(opts.init.as_deref());
    let mut run = claim(opts, RunStage::Surface, &inputs, &data.data)?;
    let data = &data.data;
    let (mut backend, cfg, start) = match fresh {
        Some((grid, cfg, bg)) => {
            let mut b = make_backend(gpu, grid)?;
            bg.install(b.as_mut())?;
            (b, cfg, 0)
        }
        None => {
            let make = |grid| make_backend(gpu, grid);
            let flags = |cfg: &SurfaceConfig| check_resume_flags(opts, cfg);
            let iters = opts.surface_iters.or(opts.iters);
            match resume::<SurfaceStage, _, _, _>(opts, iters, make, flags)? {
                Ok(resumed) => resumed,
                Err(done) => return Ok(done),
            }
        }
    };
    run.write_info(&run_info(opts, data, opts.init.clone())?)?;
    eprintln!(
        "stage 2 on {} ({}): preset {}, category {}, {} steps of {} rays, a {} → {}, count {}, \
         δ rate {:.1e}",
        backend.name(),
        gpu.map_or("rayon".to_string(), |g| g.info().name.clone()),
        cfg.preset,
        cfg.category,
        cfg.iters,
        cfg.batch,
        cfg.a.start,
        cfg.a.end,
        cfg.truncation_count.name(),
        cfg.lr_delta.init
    );
    let (report, rendered) =
        surface_steps::train(backend.as_mut(), data, &cfg, &opts.out, start, !opts.quiet)?;
    let r = &report.run;
    let per_ray = &r.per_ray;
    let figures = SurfaceFigures {
        per_ray: Some(SurfacePerRay {
            cells: per_ray.cells,
            solves: per_ray.solves,
            culled_solves: per_ray.culled,
            hits: per_ray.hits,
            cut_hits: per_ray.cut,
            guarded_hits: per_ray.guarded,
            atomic_adds: per_ray.atomic_adds,
            blocks_skipped: Some(per_ray.blocks_skipped),
        }),
        vertices_before_prune: Some(report.vertices_before_prune),
        allocated_vertices: report.allocated_vertices,
    };
    let trainer = Trainer::of(RunStage::Surface, backend.as_ref(), gpu, data, timing)?;
    trainer.finish(&run, (r, rendered), |s| s, figures, cfg)
}

/// The flags `--resume` refuses to change in a stage-2 run.
fn check_resume_flags(opts: &TrainOptions, cfg: &SurfaceConfig) -> Result<()> {
    let clashes = [
        ("--batch", opts.batch.is_some_and(|b| b != cfg.batch)),
        (
            "--category",
            opts.category.is_some_and(|c| c != cfg.category),
        ),
        ("--preset", opts.preset.is_some_and(|p| p != cfg.preset)),
        ("--set", !opts.set.is_empty()),
        ("--alpha-init-scale", opts.alpha_init_scale.is_some()),
    ];
    let kept = format!(
        "batch {}, category {}, preset {}",
        cfg.batch, cfg.category, cfg.preset
    );
    refuse_clashes(&clashes, &kept, "--surface-iters / --iters")
}
