//! Stage 1 (Plenoxels) as a library call: claim the run directory, start a grid or resume the
//! checkpoint, train, and write `metrics.json` ([`PlenoxelsMetrics`]).

use super::metrics::{PlenoxelsMetrics, PlenoxelsSeconds, SamplesPerRay};
use super::train_options::TrainOptions;
use super::train_run::{check_resumed_data, refuse_clashes, resume, run_info, Loaded, Trained};
use crate::checkpoint::BackgroundRecord;
use crate::data::dataset::peak_rss_bytes;
use crate::gpu::Gpu;
use crate::grid::Grid;
use crate::plenoxel::{CpuPlenoxels, PlenoxelsBackend, PlenoxelsStage, VulkanPlenoxels};
use crate::run::{RunDir, RunStage};
use crate::train::{plenoxels_steps, PlenoxelsConfig};
use anyhow::Result;
use std::time::Instant;

/// The Vulkan backend on `gpu`, or the CPU backend when there is none.
pub fn make_backend(gpu: Option<&Gpu>, grid: Grid) -> Result<Box<dyn PlenoxelsBackend>> {
    Ok(match gpu {
        Some(gpu) => Box::new(VulkanPlenoxels::new(gpu, grid)?),
        None => Box::new(CpuPlenoxels::new(grid)),
    })
}

/// Train stage 1 into `opts.out` on `gpu` (`None`: the CPU twins).
pub fn train_plenoxels(
    opts: &TrainOptions,
    data: &Loaded,
    gpu: Option<&Gpu>,
) -> Result<Trained<PlenoxelsMetrics>> {
    let t_all = Instant::now();
    // A new run's flags are checked before its folder is claimed.
    let fresh_cfg = if opts.resume {
        None
    } else {
        let cfg = opts.plenoxels_config()?;
        opts.check_plenoxels_memory(&cfg)?;
        Some(cfg)
    };
    let mut run = RunDir::claim(
        &opts.out,
        RunStage::Plenoxels,
        opts.open_mode(),
        &[&opts.data],
    )?;
    let (load_s, data) = (data.seconds, &data.data);
    if opts.resume {
        check_resumed_data(opts, data)?;
    }
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
        let make = |grid| make_backend(gpu, grid);
        let flags = |cfg: &PlenoxelsConfig| check_resume_flags(opts, cfg);
        match resume::<PlenoxelsStage, _, _, _>(opts, opts.iters, make, flags)? {
            Ok(resumed) => resumed,
            Err(done) => return Ok(done),
        }
    };
    run.write_info(&run_info(opts, data, None)?)?;
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
        plenoxels_steps::train(backend.as_mut(), data, &cfg, &opts.out, start, !opts.quiet)?;
    let spr = &report.run.per_ray;
    let metrics = PlenoxelsMetrics {
        stage: RunStage::Plenoxels.name().into(),
        backend: backend.name().into(),
        device: gpu.map(|g| g.info().name.clone()),
        wall_seconds: PlenoxelsSeconds {
            load: load_s,
            train: report.run.train_seconds,
            upsample: report.upsample_seconds,
            checkpoint: report.run.checkpoint_seconds,
            render_test: report.run.render_seconds,
            total: load_s + t_all.elapsed().as_secs_f64(),
        },
        train_rays_per_s: report.run.train_rays_per_s,
        final_train_mse: report.run.final_mse,
        test_psnr: report.run.test_psnr,
        test_psnr_per_view: rendered.psnr,
        samples_per_ray: Some(SamplesPerRay {
            shaded: spr.shaded,
            empty: spr.empty,
            skipped: spr.skipped,
        }),
        atomic_adds_per_ray: Some(spr.atomic_adds),
        allocated_vertices: report.allocated_vertices,
        bytes_per_vertex: report.bytes_per_vertex,
        peak_rss_bytes: peak_rss_bytes(),
        background: BackgroundRecord::of(data.background, &backend.background()?),
        config: cfg,
    };
    run.write_metrics(&metrics)?;
    Ok(Trained::Done(metrics))
}

/// The flags `--resume` refuses to change in a stage-1 run.
fn check_resume_flags(opts: &TrainOptions, cfg: &PlenoxelsConfig) -> Result<()> {
    let final_res = cfg.upsample.last().map_or(cfg.res, |u| u.1);
    let clashes = [
        ("--res", opts.res.is_some_and(|r| r != final_res)),
        ("--batch", opts.batch.is_some_and(|b| b != cfg.batch)),
        ("--preset", opts.preset.is_some_and(|p| p != cfg.preset)),
        ("--plenoxels-set", !opts.plenoxels_set.is_empty()),
    ];
    let kept = format!(
        "grid {final_res}³, batch {}, preset {}",
        cfg.batch, cfg.preset
    );
    refuse_clashes(&clashes, &kept, "--iters")
}
