//! `export` and `import` as library calls: a run's stage-1 grid to an svox2 `ckpt.npz`, and an
//! svox2 checkpoint to a finished stage-1 run directory.

use crate::grid::Grid;
use crate::run::{self, Open, RunDir, RunInfo, RunStage};
use crate::train::{PlenoxelsConfig, Preset};
use anyhow::{Context, Result};
use serde_json::json;
use std::path::PathBuf;

/// Options of `export` (its command-line flags).
#[derive(clap::Args, Debug)]
pub struct ExportOptions {
    /// A run directory written by `train` (or `import`).
    #[arg(long)]
    pub run: PathBuf,
    /// Output svox2 checkpoint (`ckpt.npz`: links, density_data, sh_data, radius, center).
    #[arg(long)]
    pub out: PathBuf,
}

/// Options of `import` (its command-line flags).
#[derive(clap::Args, Debug)]
pub struct ImportOptions {
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

/// `export`: the run's stage-1 grid as an svox2 checkpoint (written atomically); returns
/// the grid.
pub fn export(opts: &ExportOptions) -> Result<Grid> {
    let ckpt_path = run::dir::plenoxels_checkpoint(&opts.run, "export")?;
    run::outputs::check_output_file(&opts.out, &[&ckpt_path])?;
    let ck = crate::checkpoint::format::load(&ckpt_path)?;
    crate::grid::npz::save_svox2(&ck.grid, &opts.out)?;
    Ok(ck.grid)
}

/// `import`: an svox2 checkpoint becomes a finished stage-1 run directory; returns
/// the grid.
pub fn import(opts: &ImportOptions) -> Result<Grid> {
    let grid = crate::grid::npz::load_svox2(&opts.ckpt)?;
    let data = std::fs::canonicalize(&opts.data)
        .with_context(|| format!("dataset {}", opts.data.display()))?;
    let open = if opts.overwrite {
        Open::Overwrite
    } else {
        Open::Fresh
    };
    let run = RunDir::claim(&opts.out, RunStage::Plenoxels, open, &[&opts.ckpt, &data])?;
    let mut cfg = PlenoxelsConfig::paper();
    cfg.preset = Preset::Imported;
    cfg.res = grid.res[0];
    cfg.upsample.clear();
    cfg.iters = 0;
    let meta =
        json!({ "stage": "plenoxels", "step": 0, "config": cfg, "imported_from": opts.ckpt });
    let n = grid.allocated();
    let info = RunInfo {
        stage: None,
        data,
        downscale: 1,
        background: crate::data::BackgroundMode::White,
        scene_scale: None,
        scene_box: None,
        ndc: None,
        identity: None,
        init: None,
        imported_from: Some(opts.ckpt.clone()),
    };
    // Built beside the run and swapped in whole: a failure leaves a previous run as it was.
    run.write_whole(&info, |dir| {
        crate::checkpoint::format::save(
            &dir.join(run::dir::PLENOXELS_CHECKPOINT),
            &grid,
            &[
                ("rms_density", &vec![0.0; n]),
                ("rms_sh", &vec![0.0; n * crate::grid::SH_DIM]),
            ],
            &meta,
        )
    })?;
    Ok(grid)
}
