//! The stage-1 (Plenoxels) training loop: batches of training rays, one backend step each,
//! upsampling with weight pruning on schedule, periodic atomic checkpoints written in the
//! background (resumable), NaN/Inf detection, and the end-of-run test renders, PSNR and
//! metrics.json.

use super::background::{self, BackgroundRecord};
use super::config::Stage1Config;
use super::progress::{pair, Progress, StepGroup, Throughput};
use super::render::{psnr, render_split, RenderedSplit};
use crate::abi::buffers::PlenoxelPerRay;
use crate::data::{BackgroundMode, Dataset, Split, TrainViews};
use crate::grid::{checkpoint, dilate, upsample, Grid};
use crate::plenoxel::{Plenoxels, StepParams, TvParams};
use crate::run::checkpoint_writer::{BackgroundSave, Cadence};
use crate::run::interrupt::{self, Interrupted};
use crate::run::memory;
use crate::run::train_log;
use anyhow::{bail, Context, Result};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use serde_json::json;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// File name of the stage-1 checkpoint inside a run directory.
pub const CHECKPOINT: &str = crate::run::dir::STAGE1_CHECKPOINT;

/// Per-step training log inside a run directory: CSV with the header [`TRAIN_LOG_HEADER`], one
/// row per step (`step` = steps done, `psnr_batch` = PSNR of that step's batch MSE, `elapsed_s` =
/// seconds since this process started training; the figures are read in groups of up to
/// `READ_EVERY` steps, whose wall time is spread evenly over them). A resumed run cuts it back to
/// the checkpoint's step and appends to it (see [`crate::run::train_log`]).
pub const TRAIN_LOG: &str = crate::run::dir::TRAIN_LOG;

/// Header line of [`TRAIN_LOG`].
pub const TRAIN_LOG_HEADER: &str = "step,mse,psnr_batch,elapsed_s";

/// Wall time per phase and throughput of a finished run.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Stage1Report {
    pub steps: u32,
    pub train_seconds: f64,
    pub upsample_seconds: f64,
    pub checkpoint_seconds: f64,
    pub render_seconds: f64,
    /// Training rays per second over the steps after the first 10 (warm-up: pipeline compiles).
    pub train_rays_per_s: f64,
    pub final_mse: f64,
    pub test_psnr: f64,
    /// Per training ray: the march's counters (samples shaded, evaluated at σ ≤ ε, skipped by
    /// the occupancy volume; gradient atomic adds).
    pub samples_per_ray: PlenoxelPerRay,
    pub allocated_vertices: usize,
    pub bytes_per_vertex: f64,
}

/// Seeded per step, so a resumed run draws the same batches as an uninterrupted one: its first
/// draw seeds the step's ray batch (`cpu::sample_rays`, a function of that seed alone).
pub(crate) fn step_rng(seed: u64, step: u32) -> Pcg64 {
    Pcg64::seed_from_u64(seed ^ (step as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15))
}

/// Rays (6 floats each) of every `stride`-th pixel per axis of every view of a split.
fn strided_rays(data: &Dataset, split: &Split, stride: u32) -> Vec<f32> {
    let mut rays = Vec::new();
    for f in &split.frames {
        for y in (0..split.height()).step_by(stride as usize) {
            for x in (0..split.width()).step_by(stride as usize) {
                let (o, d) = f.camera.pixel_ray(x, y);
                rays.extend_from_slice(&data.scene.to_scaled(o).to_array());
                rays.extend_from_slice(&d.to_array());
            }
        }
    }
    rays
}

/// Prune by training-ray weight, dilate twice, resample to `new_res` (optimiser state resets).
fn upsample_step(
    backend: &mut dyn Plenoxels,
    data: &Dataset,
    cfg: &Stage1Config,
    new_res: u32,
) -> Result<()> {
    let grid = backend.grid()?;
    let rays = strided_rays(data, &data.train, cfg.prune_pixel_stride);
    let mut weights = vec![0f32; grid.allocated()];
    for chunk in rays.chunks(6 * 262_144) {
        let w = backend.max_weights(chunk, cfg.prune_stop_thresh)?;
        for (a, b) in weights.iter_mut().zip(w) {
            *a = a.max(b);
        }
    }
    let keep: Vec<bool> = grid
        .links
        .iter()
        .map(|&l| l >= 0 && weights[l as usize] >= cfg.prune_weight)
        .collect();
    let keep = dilate(grid.res, &keep, 2);
    // Refused before the rows are allocated (a barely trained grid keeps nearly every vertex).
    let next = upsample(&grid, new_res, &keep, |vertices| {
        memory::ensure_fits(
            &format!("upsampling to {new_res}³ ({vertices} vertices kept)"),
            Grid::training_bytes([new_res; 3], vertices),
        )
        .context(
            "too few vertices were pruned by training-ray weight before the upsampling \
             (more --iters, or a smaller --res)",
        )
    })?;
    if next.allocated() == 0 {
        bail!(
            "upsampling to {new_res}³ kept no vertex (no training-ray weight reached {}); \
             the scene may be empty, its cameras may not see the scene box (see the warnings \
             of `alphasurf inspect` on the dataset) or training diverged",
            cfg.prune_weight
        );
    }
    backend.load(next, None)
}

/// Check grid and optimiser state for NaN/Inf; the error names the first offender.
fn check_finite(grid: &Grid, step: u32) -> Result<()> {
    for (name, v) in [("density", &grid.density), ("sh", &grid.sh)] {
        if let Some(i) = v.iter().position(|x| !x.is_finite()) {
            bail!(
                "non-finite {name} value {} at vertex row {i} after step {step}",
                v[i]
            );
        }
    }
    Ok(())
}

/// The metadata of the checkpoint of `step` (with the background of a run in `mode`).
fn meta(
    backend: &dyn Plenoxels,
    cfg: &Stage1Config,
    mode: BackgroundMode,
    step: u32,
) -> Result<serde_json::Value> {
    let bg = BackgroundRecord::of(mode, &backend.background()?);
    Ok(json!({
        "stage": "plenoxels", "step": step, "config": cfg, background::META_KEY: bg
    }))
}

/// Write the checkpoint of `step` atomically, now (refuses non-finite values).
fn save(
    backend: &dyn Plenoxels,
    cfg: &Stage1Config,
    mode: BackgroundMode,
    out: &Path,
    step: u32,
) -> Result<()> {
    let meta = meta(backend, cfg, mode, step)?;
    backend.with_state(&mut |grid, [sd, ss]| {
        check_finite(grid, step)?;
        checkpoint::save(
            &out.join(CHECKPOINT),
            grid,
            &[("rms_density", sd), ("rms_sh", ss)],
            &meta,
        )
    })
}

/// The checkpoint of `step` as a write for the checkpoint thread: the grid and the running
/// averages are copied (downloaded from a GPU) now, checked and written atomically there.
fn snapshot(
    backend: &dyn Plenoxels,
    cfg: &Stage1Config,
    mode: BackgroundMode,
    out: &Path,
    step: u32,
) -> Result<impl FnOnce() -> Result<()> + Send + 'static> {
    let meta = meta(backend, cfg, mode, step)?;
    let grid = backend.grid()?;
    let (sd, ss) = backend.optimizer_state()?;
    let path = out.join(CHECKPOINT);
    Ok(move || {
        check_finite(&grid, step)?;
        checkpoint::save(
            &path,
            &grid,
            &[("rms_density", &sd), ("rms_sh", &ss)],
            &meta,
        )
    })
}

/// Restore grid, optimiser state, background and step from a run's checkpoint; returns the next
/// step, the configuration and the background.
pub fn resume(
    backend: &mut dyn Plenoxels,
    path: &Path,
) -> Result<(u32, Stage1Config, BackgroundRecord)> {
    let ck = checkpoint::load(path)?;
    let (step, cfg) = checkpoint::meta_step_config::<Stage1Config>(&ck.meta, "plenoxels", path)?;
    cfg.validate()
        .with_context(|| format!("{}: invalid configuration", path.display()))?;
    let state = |name: &str| checkpoint::optim_array(&ck.optim, name, path);
    let state = (state("rms_density")?, state("rms_sh")?);
    let bg = BackgroundRecord::from_meta(&ck.meta, path)?;
    backend.load(ck.grid, Some(state))?;
    backend.set_background(bg.kernel())?;
    Ok((step, cfg, bg))
}

/// Train stage 1 from `start_step` (0, or the step after a resumed checkpoint) to `cfg.iters`,
/// then render the test split into `out/test/` and write `out/metrics.json`. From step 0 the
/// background starts as `data.background` says (`BackgroundRecord::start_on`); a resumed run
/// keeps the one `resume` restored.
pub fn train(
    backend: &mut dyn Plenoxels,
    data: &Dataset,
    cfg: &Stage1Config,
    out: &Path,
    start_step: u32,
    show_progress: bool,
) -> Result<(Stage1Report, RenderedSplit)> {
    std::fs::create_dir_all(out)
        .with_context(|| format!("creating run directory {}", out.display()))?;
    let _catch = interrupt::catch();
    let mut report = Stage1Report::default();
    let mut progress = Progress::new(cfg.iters as u64, start_step as u64, show_progress);
    let mut throughput = Throughput::new(start_step);
    let mut sample_totals = PlenoxelPerRay::default();
    let mut mse = f64::NAN;
    let log_path = out.join(TRAIN_LOG);
    let mut log = train_log::open(&log_path, TRAIN_LOG_HEADER, start_step)?;
    let views = TrainViews::new(&data.train, &data.scene)?;
    let t_train = Instant::now();
    if start_step == 0 {
        backend.set_background(BackgroundRecord::start_on(data).kernel())?;
    }
    let mut group = StepGroup::default();
    let mut writer = BackgroundSave::default();
    let mut cadence = Cadence::new(cfg.checkpoint_every, cfg.checkpoint_min_seconds);
    for step in start_step..cfg.iters {
        if let Some((_, r)) = cfg.upsample.iter().find(|(s, _)| *s == step) {
            let t = Instant::now();
            progress.message(&format!(
                "upsampling to {r}³ (pruning by training-ray weight)"
            ));
            upsample_step(backend, data, cfg, *r)?;
            report.upsample_seconds += t.elapsed().as_secs_f64();
            group.restart();
        }
        let mut rng = step_rng(cfg.seed, step);
        let batch_seed: u64 = rng.random();
        let tv_on = !(cfg.tv_until_upsample && cfg.upsample.iter().any(|(s, _)| *s <= step));
        let slots = cfg.res_at(step).pow(3);
        let count = ((slots as f32 * cfg.tv_fraction) as u32).max(1);
        let tv = (tv_on && (cfg.tv_sigma > 0.0 || cfg.tv_sh > 0.0)).then(|| TvParams {
            start: rng.random_range(0..=slots - count),
            count,
            lambda_sigma: cfg.tv_sigma,
            lambda_sh: cfg.tv_sh,
        });
        backend.step_sampled(
            &views,
            batch_seed,
            cfg.batch as usize,
            &StepParams {
                lr_sigma: cfg.lr_sigma.at(step),
                lr_sh: cfg.lr_sh.at(step),
                beta: cfg.beta,
                eps: cfg.eps,
                stop_thresh: cfg.stop_thresh,
                tv,
                // A learned background is a colour, as the SH are: it steps at their rate.
                lr_bg: cfg.lr_sh.at(step),
            },
        )?;
        group.push(step);
        // A signal asked for a stop: this step's checkpoint, then out (after the last step the
        // run ends anyway).
        let stop = interrupt::requested().filter(|_| step + 1 < cfg.iters);
        let checkpoint = cadence.due(step, cfg.iters) || stop.is_some();
        // Read the group before an upsampling, so that its wall time is the training's alone.
        let upsample_next = cfg.upsample.iter().any(|(s, _)| *s == step + 1);
        if group.due(step, cfg.iters, checkpoint || upsample_next) {
            let (steps, secs) = group.take();
            let n = steps.len();
            let before = t_train.elapsed().as_secs_f64() - secs;
            for (i, (s, stats)) in pair(steps, backend.take_stats()?)?.into_iter().enumerate() {
                if !stats.mse.is_finite() {
                    bail!(
                        "non-finite loss at step {s} ({}); the last good checkpoint is {}",
                        stats.mse,
                        out.join(CHECKPOINT).display()
                    );
                }
                mse = stats.mse;
                // The group's wall time, spread evenly over its steps.
                let elapsed = before + secs * (i + 1) as f64 / n as f64;
                writeln!(log, "{},{mse:e},{:.4},{elapsed:.3}", s + 1, psnr(mse))
                    .with_context(|| format!("writing {}", log_path.display()))?;
                throughput.add(s, cfg.batch as usize, secs / n as f64);
                sample_totals.add(&stats.counts);
            }
            progress.step(step as u64 + 1, mse, throughput.rays_per_s());
            report.train_seconds += secs;
        }
        if checkpoint {
            let t = Instant::now();
            train_log::flush(&mut log, &log_path)?;
            writer.checkpoint(
                backend.state_bytes(),
                || snapshot(backend, cfg, data.background, out, step + 1),
                || save(backend, cfg, data.background, out, step + 1),
            )?;
            report.checkpoint_seconds += t.elapsed().as_secs_f64();
            group.restart();
        }
        if let Some(signal) = stop {
            progress.finish();
            let ck = out.join(CHECKPOINT);
            return Err(Interrupted::after_checkpoint(
                signal,
                step + 1,
                cfg.iters,
                ck,
                &mut writer,
            ));
        }
    }
    progress.finish();
    train_log::flush(&mut log, &log_path)?;
    drop(log);
    // The last checkpoint is written while the test views render.
    let t = Instant::now();
    writer.checkpoint(
        backend.state_bytes(),
        || snapshot(backend, cfg, data.background, out, cfg.iters),
        || save(backend, cfg, data.background, out, cfg.iters),
    )?;
    report.checkpoint_seconds += t.elapsed().as_secs_f64();

    let t = Instant::now();
    let rendered = render_split(
        backend,
        data,
        &data.test,
        cfg.stop_thresh,
        &out.join("test"),
        1,
    )?;
    report.render_seconds = t.elapsed().as_secs_f64();
    let t = Instant::now();
    writer.finish()?;
    report.checkpoint_seconds += t.elapsed().as_secs_f64();
    let (res, rows) = backend.shape();
    report.steps = cfg.iters;
    report.train_rays_per_s = throughput.run_rays_per_s();
    report.final_mse = mse;
    report.test_psnr = rendered.mean_psnr;
    report.samples_per_ray = sample_totals.scaled(1.0 / throughput.rays().max(1) as f64);
    report.allocated_vertices = rows;
    report.bytes_per_vertex = Grid::training_bytes(res, rows) / rows.max(1) as f64;
    Ok((report, rendered))
}

/// The run directory's checkpoint path.
pub fn checkpoint_path(run: &Path) -> PathBuf {
    run.join(CHECKPOINT)
}
