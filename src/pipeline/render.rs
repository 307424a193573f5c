//! `render` as a library call: a split of a trained stage-1 run rendered to PNG, with PSNR: the
//! images composited, and the views rendered, on the run's background.

use super::train_stage1::make_backend;
use crate::backend::Backend;
use crate::data::{Dataset, LoadOptions};
use crate::gpu::Gpu;
use crate::run::{self, read_info};
use crate::train::{render_split, BackgroundRecord, RenderedSplit, Stage1Config};
use anyhow::{bail, Result};
use std::path::PathBuf;

/// Options of `render` (its command-line flags).
#[derive(clap::Args, Debug)]
pub struct RenderOptions {
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

/// Render the split `opts.split` of the run `opts.run` into `opts.out` on `gpu` (`None`: the CPU
/// twins); returns the per-view and mean PSNR.
pub fn render(opts: &RenderOptions, gpu: Option<&Gpu>) -> Result<RenderedSplit> {
    let ckpt_path = run::dir::stage1_checkpoint(&opts.run, "render")?;
    let ckpt = crate::grid::checkpoint::load(&ckpt_path)?;
    let bg = BackgroundRecord::from_meta(&ckpt.meta, &ckpt_path)?;
    let info = read_info(&opts.run);
    let data_dir = match (&opts.data, &info) {
        (Some(d), _) => d.clone(),
        (None, Ok(i)) => i.data.clone(),
        (None, Err(e)) => bail!("{e:#} (or pass --data)"),
    };
    // The images at the size the run was trained on, so the PSNR is the one training reported.
    let downscale = info.as_ref().map_or(1, |i| i.downscale);
    run::outputs::check_output_dir(&opts.out, &[&ckpt_path, &data_dir])?;
    let data = Dataset::load(
        &data_dir,
        &LoadOptions {
            background: bg.mode,
            downscale,
            ..Default::default()
        },
    )?;
    let split = match opts.split.as_str() {
        "train" => &data.train,
        "val" => data.val(),
        "test" => &data.test,
        s => bail!("--split {s}: expected train, val or test"),
    };
    let stop = serde_json::from_value::<Stage1Config>(ckpt.meta["config"].clone())
        .map(|c| c.stop_thresh)
        .unwrap_or(1e-7);
    let mut backend = make_backend(gpu, ckpt.grid)?;
    backend.set_background(bg.kernel())?;
    let r = render_split(backend.as_mut(), &data, split, stop, &opts.out)?;
    Ok(r)
}
