//! `alphasurf train --stage surface`: initialise the αSurf grid from a stage-1 run or an svox2
//! checkpoint (method.md §3.1), or resume a stage-2 run, and train it.

use super::resume::resume;
use super::train::{open_mode, run_info, Loaded, TrainArgs};
use crate::data::dataset::peak_rss_bytes;
use crate::gpu::Gpu;
use crate::grid::surface::SurfaceGrid;
use crate::grid::{npz, Grid};
use crate::run::{RunDir, RunStage};
use crate::surface::{CpuSurface, SurfaceBackend, VulkanSurface};
use crate::train::{stage1, stage2, Category, Preset, SurfaceConfig};
use anyhow::{ensure, Context, Result};
use serde_json::json;
use std::path::Path;
use std::time::Instant;

/// The Vulkan backend on `gpu`, or the CPU backend when there is none.
fn make_backend(gpu: Option<&Gpu>, grid: SurfaceGrid) -> Result<Box<dyn SurfaceBackend>> {
    Ok(match gpu {
        Some(gpu) => {
            grid.validate()?;
            Box::new(VulkanSurface::new(gpu, grid)?)
        }
        None => Box::new(CpuSurface::new(grid)?),
    })
}

/// The stage-1 grid `--init` names: a run directory (its plenoxels.npz) or an npz file.
fn load_init(path: &Path) -> Result<Grid> {
    let file = if path.is_dir() {
        let ck = stage1::checkpoint_path(path);
        ensure!(
            ck.exists(),
            "--init {}: no {} in that directory (is it a stage-1 run?)",
            path.display(),
            stage1::CHECKPOINT
        );
        ck
    } else {
        path.to_path_buf()
    };
    npz::load_svox2(&file).with_context(|| format!("--init {}", path.display()))
}

/// The stage-2 configuration for a stage-1 grid of `grid_n`³ vertices: the preset fitted to the
/// grid, then the command line's overrides.
fn config(args: &TrainArgs, grid_n: u32) -> Result<SurfaceConfig> {
    let mut cfg = SurfaceConfig::preset(args.preset, args.category)?;
    cfg.fit_grid(grid_n);
    cfg.seed = args.seed;
    if let Some(n) = args.surface_iters.or(args.iters) {
        ensure!(n > 0, "the number of stage-2 steps must be at least 1");
        let preset = cfg.preset;
        cfg = cfg.scaled(n);
        cfg.preset = preset;
    }
    if let Some(b) = args.batch {
        ensure!(b > 0, "--batch must be at least 1");
        cfg.batch = b;
    }
    if let Some(c) = args.checkpoint_every {
        ensure!(c > 0, "--checkpoint-every must be at least 1");
        cfg.checkpoint_every = c;
    }
    for kv in &args.set {
        cfg = set_field(&cfg, kv)?;
    }
    if let Some(s) = args.alpha_init_scale {
        ensure!(
            s > 0.0 && s.is_finite(),
            "--alpha-init-scale must be positive, got {s}"
        );
        cfg.init.alpha_init_scale = s;
    }
    cfg.validate()?;
    Ok(cfg)
}

/// `--set key.path=json`: patch one field of the configuration.
fn set_field(cfg: &SurfaceConfig, kv: &str) -> Result<SurfaceConfig> {
    let (key, value) = kv
        .split_once('=')
        .with_context(|| format!("--set {kv}: expected KEY=VALUE"))?;
    let value: serde_json::Value = serde_json::from_str(value)
        .or_else(|_| serde_json::from_str(&format!("\"{value}\"")))
        .with_context(|| format!("--set {kv}: the value is not JSON"))?;
    let mut v = serde_json::to_value(cfg)?;
    let mut slot = &mut v;
    for part in key.split('.') {
        slot = slot
            .get_mut(part)
            .with_context(|| format!("--set {kv}: no configuration field {key:?}"))?;
    }
    ensure!(
        std::mem::discriminant(slot) == std::mem::discriminant(&value)
            || (slot.is_number() && value.is_number()),
        "--set {kv}: {key} is {slot}, not {value}"
    );
    *slot = value;
    serde_json::from_value(v).with_context(|| format!("--set {kv}: invalid value for {key}"))
}

/// A new stage-2 grid and its configuration from `--init` and the flags.
fn fresh_start(args: &TrainArgs) -> Result<(SurfaceGrid, SurfaceConfig)> {
    let init = args
        .init
        .as_ref()
        .context("stage 2 needs --init STAGE1_RUN_DIR or --init ckpt.npz")?;
    let density = load_init(init)?;
    let cfg = config(args, density.res.into_iter().max().unwrap_or(0))?;
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
    Ok((grid, cfg))
}

/// Run stage 2.
pub fn run(args: &TrainArgs, data: &Loaded, gpu: Option<&Gpu>) -> Result<()> {
    let t_all = Instant::now();
    // A new run's inputs and flags are checked before its folder is claimed.
    let fresh = if args.resume {
        None
    } else {
        Some(fresh_start(args)?)
    };
    let mut inputs = vec![args.data.as_path()];
    inputs.extend(args.init.as_deref());
    let mut run = RunDir::claim(&args.out, RunStage::Surface, open_mode(args), &inputs)?;
    let (load_s, data) = (data.seconds, &data.data);
    let ckpt = stage2::checkpoint_path(&args.out);
    let (mut backend, cfg, start) = match fresh {
        Some((grid, cfg)) => (make_backend(gpu, grid)?, cfg, 0),
        None => {
            let restore = || {
                let probe = SurfaceGrid::load(&ckpt)?;
                let mut b = make_backend(gpu, probe.grid)?;
                let (step, cfg) = stage2::resume(b.as_mut(), &ckpt)?;
                check_resume_flags(args, &cfg)?;
                Ok((b, step, cfg))
            };
            let iters = args.surface_iters.or(args.iters);
            match resume(&ckpt, iters, |c: &mut SurfaceConfig| &mut c.iters, restore)? {
                Some(resumed) => resumed,
                None => return Ok(()),
            }
        }
    };
    run.write_info(&run_info(args, args.init.clone())?)?;
    eprintln!(
        "stage 2 on {} ({}): preset {}, category {}, {} steps of {} rays, a {} → {}, δ rate {:.1e}",
        backend.name(),
        gpu.map_or("rayon".to_string(), |g| g.info().name.clone()),
        cfg.preset,
        cfg.category,
        cfg.iters,
        cfg.batch,
        cfg.a.start,
        cfg.a.end,
        cfg.lr_delta.init
    );
    let (report, rendered) =
        stage2::train(backend.as_mut(), data, &cfg, &args.out, start, !args.quiet)?;
    for (i, p) in rendered.psnr.iter().enumerate() {
        println!("test view {i:>3}: PSNR {p:.2} dB");
    }
    let r = report.per_ray;
    println!(
        "per training ray: {:.1} cells read ({:.1} empty blocks skipped), {:.2} cubic solves \
         ({:.1} skipped by min/max or segment culling), {:.2} hits, {:.2} cut by truncation, {:.3} guarded, \
         {:.1} gradient atomic adds",
        r[0], r[7], r[1], r[2], r[3], r[4], r[5], r[6]
    );
    println!(
        "stage 2 done: test PSNR {:.2} dB, {:.0} training rays/s, {} vertices after dropping \
         α < {} ({} before), {:.1} s",
        report.test_psnr,
        report.train_rays_per_s,
        report.allocated_vertices,
        cfg.prune_alpha,
        report.vertices_before_prune,
        load_s + t_all.elapsed().as_secs_f64()
    );
    let metrics = json!({
        "stage": "surface",
        "backend": backend.name(),
        "device": gpu.map(|g| g.info().name.clone()),
        "wall_seconds": {
            "load": load_s,
            "train": report.train_seconds,
            "checkpoint": report.checkpoint_seconds,
            "render_test": report.render_seconds,
            "total": load_s + t_all.elapsed().as_secs_f64(),
        },
        "train_rays_per_s": report.train_rays_per_s,
        "final_train_mse": report.final_mse,
        "test_psnr": report.test_psnr,
        "test_psnr_per_view": rendered.psnr,
        "per_ray": {
            "cells": r[0], "solves": r[1], "culled_solves": r[2], "hits": r[3],
            "cut_hits": r[4], "guarded_hits": r[5], "atomic_adds": r[6], "blocks_skipped": r[7],
        },
        "vertices_before_prune": report.vertices_before_prune,
        "allocated_vertices": report.allocated_vertices,
        "peak_rss_bytes": peak_rss_bytes(),
        "config": cfg,
    });
    run.write_metrics(&metrics)
}

/// On `--resume` the checkpoint's configuration wins: a flag that asks for something else is an
/// error rather than silently ignored.
fn check_resume_flags(args: &TrainArgs, cfg: &SurfaceConfig) -> Result<()> {
    let clashes = [
        ("--batch", args.batch.is_some_and(|b| b != cfg.batch)),
        (
            "--category",
            args.category != Category::Thin && args.category != cfg.category,
        ),
        (
            "--preset",
            args.preset != Preset::Fast && args.preset != cfg.preset,
        ),
        ("--set", !args.set.is_empty()),
        ("--alpha-init-scale", args.alpha_init_scale.is_some()),
    ];
    let named: Vec<&str> = clashes.iter().filter(|c| c.1).map(|c| c.0).collect();
    ensure!(
        named.is_empty(),
        "--resume continues the checkpoint's configuration (batch {}, category {}, preset {}); \
         {} cannot change it (only --surface-iters / --iters can)",
        cfg.batch,
        cfg.category,
        cfg.preset,
        named.join(", ")
    );
    Ok(())
}
