//! `render` as a library call: a split of a trained run rendered to PNG, with PSNR: the images
//! composited, and the views rendered, on the run's background. A stage-1 run renders its density
//! grid; a stage-2 run its surfaces, truncated as at the checkpoint's step (after training: as
//! the test renders `train` wrote).

use super::{train_plenoxels, train_surface};
use crate::backend::Backend;
use crate::checkpoint::format as checkpoint;
use crate::checkpoint::Backdrop;
use crate::data::{Dataset, LoadOptions};
use crate::gpu::Gpu;
use crate::grid::surface::SurfaceGrid;
use crate::math::surface::Truncation;
use crate::run::dir::{ALL_STAGE1, ALL_STAGE2, SURFACE_CHECKPOINT};
use crate::run::{self, read_info};
use crate::train::{
    render_split, render_split_with, PlenoxelsConfig, RenderedSplit, SurfaceConfig,
    MAX_PIXEL_SAMPLES,
};
use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};

/// Options of `render` (its command-line flags).
#[derive(clap::Args, Debug)]
pub struct RenderOptions {
    /// A run directory written by `train`: a stage-1 run (its density grid) or a stage-2 run (its
    /// surfaces).
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
    /// N×N rays per pixel on a regular grid inside it, averaged: an anti-aliased render (the
    /// development set's images are pixel averages, as a path tracer filters them). 1 is one ray
    /// through the pixel centre, as `train` renders its test views and reports their PSNR.
    #[arg(long, default_value_t = 1, value_parser = pixel_samples())]
    pub pixel_samples: u32,
}

/// `--pixel-samples`: 1 to [`MAX_PIXEL_SAMPLES`].
fn pixel_samples() -> clap::builder::RangedI64ValueParser<u32> {
    clap::value_parser!(u32).range(1..=MAX_PIXEL_SAMPLES as i64)
}

/// The grid a run directory holds, with its background.
enum Trained {
    Density {
        grid: crate::grid::Grid,
        stop_thresh: f32,
    },
    Surface {
        grid: SurfaceGrid,
        /// Truncation at the checkpoint's step.
        truncation: Truncation,
        stop_thresh: f32,
    },
}

/// Load the checkpoint of the run `run`: its surface.npz (stage 2) if there is one, else its
/// plenoxels.npz (stage 1), with its background and the background's spheres.
fn load_run(run: &Path) -> Result<(Trained, Backdrop, PathBuf)> {
    let surface = crate::checkpoint::path::<crate::surface::SurfaceStage>(run);
    if surface.is_file() {
        let ck = crate::checkpoint::surface::load(&surface)?;
        let (step, cfg) =
            checkpoint::meta_step_config::<SurfaceConfig>(&ck.meta, "surface", &surface)?;
        let backdrop = Backdrop::kept(&ck.meta, &ck.optim, &surface)?;
        let trained = Trained::Surface {
            grid: ck.grid,
            truncation: cfg.truncation(step),
            stop_thresh: cfg.stop_thresh,
        };
        return Ok((trained, backdrop, surface));
    }
    if run.join(ALL_STAGE2).join(SURFACE_CHECKPOINT).is_file() {
        bail!(
            "{} is a `--stage all` run: give its stage-1 run {} or its stage-2 run {}",
            run.display(),
            run.join(ALL_STAGE1).display(),
            run.join(ALL_STAGE2).display()
        );
    }
    let path = run::dir::plenoxels_checkpoint(run, "render")?;
    let ck = checkpoint::load(&path)?;
    let backdrop = Backdrop::kept(&ck.meta, &ck.optim, &path)?;
    let stop_thresh = serde_json::from_value::<PlenoxelsConfig>(ck.meta["config"].clone())
        .map(|c| c.stop_thresh)
        .unwrap_or(1e-7);
    let trained = Trained::Density {
        grid: ck.grid,
        stop_thresh,
    };
    Ok((trained, backdrop, path))
}

/// Render the split `opts.split` of the run `opts.run` into `opts.out` on `gpu` (`None`: the CPU
/// twins); returns the per-view and mean PSNR.
pub fn render(opts: &RenderOptions, gpu: Option<&Gpu>) -> Result<RenderedSplit> {
    let (trained, backdrop, ckpt_path) = load_run(&opts.run)?;
    let info = read_info(&opts.run);
    let data_dir = match (&opts.data, &info) {
        (Some(d), _) => d.clone(),
        (None, Ok(i)) => i.data.clone(),
        (None, Err(e)) => bail!("{e:#} (or pass --data)"),
    };
    // The images at the size the run was trained on, so the PSNR is the one training reported.
    let downscale = info.as_ref().map_or(1, |i| i.downscale);
    run::outputs::check_output_dir(&opts.out, &[&ckpt_path, &data_dir])?;
    // The rays in the grid's space as the run recorded it (its box or NDC space).
    let scene = info.as_ref().ok().and_then(|i| i.scene()).map(|s| s.1);
    let data = Dataset::load(
        &data_dir,
        &LoadOptions {
            background: backdrop.record.mode,
            downscale,
            scene,
            ..Default::default()
        },
    )?;
    let split = match opts.split.as_str() {
        "train" => &data.train,
        "val" => data.val_split.as_ref().with_context(|| {
            format!(
                "--split val: {} has no validation split (no val views); use --split test",
                data.root.display()
            )
        })?,
        "test" => &data.test,
        s => bail!("--split {s}: expected train, val or test"),
    };
    match trained {
        Trained::Density { grid, stop_thresh } => {
            let mut backend = train_plenoxels::make_backend(gpu, grid)?;
            backdrop.install(backend.as_mut())?;
            render_split(
                backend.as_mut(),
                &data,
                split,
                stop_thresh,
                &opts.out,
                opts.pixel_samples,
            )
        }
        Trained::Surface {
            grid,
            truncation,
            stop_thresh,
        } => {
            let mut backend = train_surface::make_backend(gpu, grid)?;
            backdrop.install(backend.as_mut())?;
            render_split_with(
                &mut |rays| Ok(backend.render(rays, truncation, stop_thresh)?.0),
                &data,
                split,
                &opts.out,
                opts.pixel_samples,
            )
        }
    }
}
