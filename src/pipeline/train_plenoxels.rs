//! Stage 1 (Plenoxels) as a library call: claim the run directory, start a grid or resume the
//! checkpoint, train, and write `metrics.json` ([`PlenoxelsMetrics`]).

use super::metrics::{PlenoxelsFigures, PlenoxelsMetrics, PlenoxelsSeconds, SamplesPerRay};
use super::train_options::TrainOptions;
use super::train_run::{claim, refuse_clashes, resume, run_info, Loaded, Trained, Trainer};
use crate::data::Dataset;
use crate::gpu::Gpu;
use crate::grid::{Grid, InitialFill};
use crate::plenoxel::{CpuPlenoxels, PlenoxelsBackend, PlenoxelsStage, VulkanPlenoxels};
use crate::run::RunStage;
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

/// The configuration of a new stage-1 run, refused when its grid (starting as `fill` says)
/// does not fit in memory.
fn fresh_config(opts: &TrainOptions, fill: InitialFill) -> Result<PlenoxelsConfig> {
    let cfg = opts.plenoxels_config()?;
    opts.check_plenoxels_memory(&cfg, fill.share())?;
    Ok(cfg)
}

/// What a new grid on `data` allocates: the whole box when it is the cube fitted to the
/// object's bounds the layout found (a capture's foreground box, not `--box`; not NDC), else
/// the inscribed sphere.
pub fn initial_fill(data: &Dataset) -> InitialFill {
    if data.in_foreground_box() {
        InitialFill::Box
    } else {
        InitialFill::Sphere
    }
}

/// Train stage 1 into `opts.out` on `gpu` (`None`: the CPU twins).
pub fn train_plenoxels(
    opts: &TrainOptions,
    data: &Loaded,
    gpu: Option<&Gpu>,
) -> Result<Trained<PlenoxelsMetrics>> {
    let timing = (data.seconds, Instant::now());
    // A new run's flags are checked before its folder is claimed.
    let fill = initial_fill(&data.data);
    let fresh_cfg = (!opts.resume)
        .then(|| fresh_config(opts, fill))
        .transpose()?;
    let mut run = claim(opts, RunStage::Plenoxels, &[&opts.data], &data.data)?;
    let data = &data.data;
    let (mut backend, cfg, start) = if let Some(cfg) = fresh_cfg {
        let grid = Grid::sphere(
            cfg.res,
            data.scene.centre.to_array(),
            [data.scene.radius; 3],
            fill.radius(),
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
    let r = &report.run;
    let figures = PlenoxelsFigures {
        samples_per_ray: Some(SamplesPerRay {
            shaded: r.per_ray.shaded,
            empty: r.per_ray.empty,
            skipped: r.per_ray.skipped,
        }),
        atomic_adds_per_ray: Some(r.per_ray.atomic_adds),
        allocated_vertices: report.allocated_vertices,
        bytes_per_vertex: report.bytes_per_vertex,
    };
    let trainer = Trainer::of(RunStage::Plenoxels, backend.as_ref(), gpu, data, timing)?;
    let upsample = report.upsample_seconds;
    let seconds = |s| PlenoxelsSeconds::with_upsample(s, upsample);
    trainer.finish(&run, (r, rendered), seconds, figures, cfg)
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
