//! The stage-2 (αSurf) training loop: batches of training rays, one backend step each with the
//! scheduled learning rates, truncation a and regularisers; periodic atomic checkpoints written
//! in the background (resumable); NaN/Inf detection; at the end the α < 0.1 surfaces are
//! dropped, the test split rendered and metrics.json written.

use super::background::{self, BackgroundRecord};
use super::progress::{pair, Progress, StepGroup, Throughput};
use super::render::{render_split_with, RenderedSplit};
use super::stage1::step_rng;
use super::surface_config::SurfaceConfig;
use crate::abi::buffers::TrainPerRay;
use crate::abi::regularisers::{delta_tv_chunk, opacity_tv_chunk, OpacityChunk};
use crate::data::{BackgroundMode, Dataset, TrainViews};
use crate::grid::checkpoint;
use crate::grid::surface::SurfaceGrid;
use crate::math::surface::Truncation;
use crate::run::checkpoint_writer::{BackgroundSave, Cadence};
use crate::run::interrupt::{self, Interrupted};
use crate::run::train_log;
use crate::surface::{SurfaceBackend, SurfaceRegs, SurfaceStepParams};
use anyhow::{bail, Context, Result};
use rand::Rng;
use serde_json::json;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// File name of the stage-2 checkpoint inside a run directory.
pub const CHECKPOINT: &str = crate::run::dir::STAGE2_CHECKPOINT;
/// Per-step log: step, mse, batch PSNR, entropy, consistency, regulariser loss (Lα + Ln),
/// seconds since the start (a group of up to `READ_EVERY` steps read together shares its wall
/// time evenly; header [`LOG_HEADER`]); cut back to the checkpoint on resume.
pub const LOG: &str = crate::run::dir::TRAIN_LOG;
/// Header line of [`LOG`].
pub const LOG_HEADER: &str = "step,mse,psnr_batch,entropy,consistency,reg_loss,elapsed_s";

/// Wall time per phase, throughput and counters of a finished run.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Stage2Report {
    pub steps: u32,
    pub train_seconds: f64,
    pub checkpoint_seconds: f64,
    pub render_seconds: f64,
    /// Training rays per second over the steps after the first 10.
    pub train_rays_per_s: f64,
    pub final_mse: f64,
    pub test_psnr: f64,
    /// Per training ray: the training pass's counters (`TrainCounts`).
    pub per_ray: TrainPerRay,
    pub vertices_before_prune: usize,
    pub allocated_vertices: usize,
}

/// The run directory's checkpoint path.
pub fn checkpoint_path(run: &Path) -> PathBuf {
    run.join(CHECKPOINT)
}

/// The metadata of the checkpoint of `step` (with the background of a run in `mode`).
fn meta(
    backend: &dyn SurfaceBackend,
    cfg: &SurfaceConfig,
    mode: BackgroundMode,
    step: u32,
) -> Result<serde_json::Value> {
    let bg = BackgroundRecord::of(mode, &backend.background()?);
    Ok(json!({
        "stage": "surface", "step": step, "config": cfg, background::META_KEY: bg
    }))
}

/// Write the checkpoint of `step` atomically, now (refuses non-finite values).
fn save(
    backend: &dyn SurfaceBackend,
    cfg: &SurfaceConfig,
    mode: BackgroundMode,
    out: &Path,
    step: u32,
) -> Result<()> {
    let meta = meta(backend, cfg, mode, step)?;
    backend
        .with_state(&mut |grid, [sd, so, ss]| {
            grid.save(
                &out.join(CHECKPOINT),
                &[("rms_delta", sd), ("rms_opacity", so), ("rms_sh", ss)],
                &meta,
            )
        })
        .with_context(|| format!("after step {step}"))
}

/// The checkpoint of `step` as a write for the checkpoint thread: the grid and the running
/// averages are copied (downloaded from a GPU) now, checked and written atomically there.
fn snapshot(
    backend: &dyn SurfaceBackend,
    cfg: &SurfaceConfig,
    mode: BackgroundMode,
    out: &Path,
    step: u32,
) -> Result<impl FnOnce() -> Result<()> + Send + 'static> {
    let meta = meta(backend, cfg, mode, step)?;
    let grid = backend.grid()?;
    let [sd, so, ss] = backend.optimizer_state()?;
    let path = out.join(CHECKPOINT);
    Ok(move || {
        grid.save(
            &path,
            &[("rms_delta", &sd), ("rms_opacity", &so), ("rms_sh", &ss)],
            &meta,
        )
        .with_context(|| format!("after step {step}"))
    })
}

/// Restore grid, optimiser state, background and step from a stage-2 checkpoint; returns the
/// next step, the configuration and the background.
pub fn resume(
    backend: &mut dyn SurfaceBackend,
    path: &Path,
) -> Result<(u32, SurfaceConfig, BackgroundRecord)> {
    let ck = SurfaceGrid::load(path)?;
    let (step, cfg) = checkpoint::meta_step_config::<SurfaceConfig>(&ck.meta, "surface", path)?;
    cfg.validate()
        .with_context(|| format!("{}: invalid configuration", path.display()))?;
    let state = |name: &str| checkpoint::optim_array(&ck.optim, name, path);
    let state = [state("rms_delta")?, state("rms_opacity")?, state("rms_sh")?];
    let bg = BackgroundRecord::from_meta(&ck.meta, path)?;
    backend.load(ck.grid, Some(state))?;
    backend.set_background(bg.kernel())?;
    Ok((step, cfg, bg))
}

/// The scheduled parameters of step `step`, with `truncation`, for a grid of resolution `res`
/// with `rows` allocated vertices; `draws` place the random regulariser chunks (Lα's start, Ln's
/// and Lδ's start — one row for both, so that the δ rows RMSProp updates densely cover both —
/// and TVα's draw).
pub fn step_params(
    cfg: &SurfaceConfig,
    res: [u32; 3],
    rows: u32,
    step: u32,
    truncation: Truncation,
    draws: [u64; 3],
) -> SurfaceStepParams {
    let row_chunk = |fraction: f32, draw: u64| {
        let count = ((rows as f32 * fraction) as u32).clamp(1, rows.max(1));
        ((draw % rows.max(1) as u64) as u32, count)
    };
    let (la_start, la_count) = row_chunk(cfg.alpha_fraction, draws[0]);
    let (n_start, n_count) = row_chunk(cfg.normal_fraction, draws[1]);
    let tv_draw = draws[2];
    let (ln1, ln2) = (cfg.lambda_n1.at(step), cfg.lambda_n2);
    SurfaceStepParams {
        lr_delta: cfg.lr_delta.at(step),
        lr_opacity: cfg.lr_opacity.at(step),
        lr_sh: cfg.lr_sh.at(step),
        // A learned background is a colour, as the SH are: it steps at their rate.
        lr_bg: cfg.lr_sh.at(step),
        beta: cfg.beta,
        eps: cfg.eps,
        truncation,
        stop_thresh: cfg.stop_thresh,
        lambda_h: cfg.lambda_h,
        lambda_c: if step < cfg.lambda_c_until {
            cfg.lambda_c
        } else {
            0.0
        },
        regs: SurfaceRegs {
            delta_tv: (cfg.lambda_delta > 0.0 && rows > 0)
                .then(|| delta_tv_chunk(res, rows, cfg.delta_fraction, cfg.lambda_delta, draws[1])),
            opacity_tv: (cfg.lambda_tv_alpha > 0.0).then(|| {
                opacity_tv_chunk(res, cfg.tv_alpha_fraction, cfg.lambda_tv_alpha, tv_draw)
            }),
            opacity_log: (cfg.lambda_alpha > 0.0).then_some(OpacityChunk {
                rows,
                start: la_start,
                count: la_count,
                lambda: cfg.lambda_alpha,
            }),
            normals: (ln1 > 0.0 || ln2 > 0.0).then_some((n_start, n_count, ln1, ln2)),
        },
    }
}

/// Train stage 2 from `start_step` to `cfg.iters`, then prune, save, render the test split into
/// `out/test/` and write `out/metrics.json`'s report.
pub fn train(
    backend: &mut dyn SurfaceBackend,
    data: &Dataset,
    cfg: &SurfaceConfig,
    out: &Path,
    start_step: u32,
    show_progress: bool,
) -> Result<(Stage2Report, RenderedSplit)> {
    std::fs::create_dir_all(out)
        .with_context(|| format!("creating run directory {}", out.display()))?;
    let _catch = interrupt::catch();
    let log_path = out.join(LOG);
    let mut log = train_log::open(&log_path, LOG_HEADER, start_step)?;
    let mut report = Stage2Report::default();
    let mut progress = Progress::new(cfg.iters as u64, start_step as u64, show_progress);
    let mut throughput = Throughput::new(start_step);
    let mut totals = TrainPerRay::default();
    let mut mse = f64::NAN;
    let t_start = Instant::now();
    let grid0 = backend.grid()?;
    let (res, rows) = (grid0.res, grid0.delta.len() as u32);
    drop(grid0);
    let views = TrainViews::new(&data.train, &data.scene)?.focused(cfg.ray_focus)?;
    let mut group = StepGroup::default();
    let mut writer = BackgroundSave::default();
    let mut cadence = Cadence::new(cfg.checkpoint_every, cfg.checkpoint_min_seconds);
    for step in start_step..cfg.iters {
        let mut rng = step_rng(cfg.seed, step);
        let batch_seed: u64 = rng.random();
        let draws = [
            rng.random::<u32>().into(),
            rng.random::<u32>().into(),
            rng.random(),
        ];
        let p = step_params(cfg, res, rows, step, cfg.truncation(step), draws);
        backend.step_sampled(&views, batch_seed, cfg.batch as usize, &p)?;
        group.push(step);
        // A signal asked for a stop: this step's checkpoint, then out (after the last step the
        // run ends anyway).
        let stop = interrupt::requested().filter(|_| step + 1 < cfg.iters);
        let checkpoint = cadence.due(step, cfg.iters) || stop.is_some();
        if group.due(step, cfg.iters, checkpoint) {
            let (steps, secs) = group.take();
            let n = steps.len();
            let before = t_start.elapsed().as_secs_f64() - secs;
            for (i, (s, stats)) in pair(steps, backend.take_stats()?)?.into_iter().enumerate() {
                if !(stats.mse.is_finite()
                    && stats.entropy.is_finite()
                    && stats.consistency.is_finite())
                {
                    bail!(
                        "non-finite loss at step {s} (mse {}, entropy {}, consistency {}); the \
                         last good checkpoint is {}",
                        stats.mse,
                        stats.entropy,
                        stats.consistency,
                        out.join(CHECKPOINT).display()
                    );
                }
                mse = stats.mse;
                throughput.add(s, cfg.batch as usize, secs / n as f64);
                totals.add(&stats.counts);
                writeln!(
                    log,
                    "{},{:.6e},{:.3},{:.5},{:.5},{:.4e},{:.3}",
                    s + 1,
                    mse,
                    super::psnr(mse),
                    stats.entropy,
                    stats.consistency,
                    stats.reg_loss,
                    // The group's wall time, spread evenly over its steps.
                    before + secs * (i + 1) as f64 / n as f64
                )
                .with_context(|| format!("writing {}", log_path.display()))?;
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
    writer.finish()?;

    // Drop the surfaces that cannot reach α ≥ prune_alpha; the optimiser state ends with them.
    let mut grid = backend.grid()?;
    report.vertices_before_prune = grid.delta.len();
    grid.prune_transparent(cfg.prune_alpha);
    if grid.delta.is_empty() {
        bail!(
            "no surface reaches α ≥ {} after training: nothing left (training diverged?)",
            cfg.prune_alpha
        );
    }
    report.allocated_vertices = grid.delta.len();
    backend.load(grid, None)?;
    // The last checkpoint is written while the test views render.
    let t = Instant::now();
    writer.checkpoint(
        backend.state_bytes(),
        || snapshot(backend, cfg, data.background, out, cfg.iters),
        || save(backend, cfg, data.background, out, cfg.iters),
    )?;
    report.checkpoint_seconds += t.elapsed().as_secs_f64();

    let t = Instant::now();
    let truncation = cfg.truncation(cfg.iters);
    let rendered = render_split_with(
        &mut |rays| Ok(backend.render(rays, truncation, cfg.stop_thresh)?.0),
        data,
        &data.test,
        &out.join("test"),
        1,
    )?;
    report.render_seconds = t.elapsed().as_secs_f64();
    let t = Instant::now();
    writer.finish()?;
    report.checkpoint_seconds += t.elapsed().as_secs_f64();
    report.steps = cfg.iters;
    report.train_rays_per_s = throughput.run_rays_per_s();
    report.final_mse = mse;
    report.test_psnr = rendered.mean_psnr;
    report.per_ray = totals.scaled(1.0 / throughput.rays().max(1) as f64);
    Ok((report, rendered))
}
