//! `train` as library calls: [`train`] for the stage the options ask for, and `--stage all`
//! ([`train_all`]): a parent run holding stage 1 in `plenoxels/` and stage 2 in `surface/`.

use super::metrics::{PlenoxelsMetrics, SurfaceMetrics};
use super::train_options::{Stage, TrainOptions};
use super::train_run::{check_resumed_data, load_data, run_info, Trained};
use super::{train_plenoxels, train_surface};
use crate::gpu::Gpu;
use crate::run::dir::{ALL_STAGE1, ALL_STAGE2};
use crate::run::{RunDir, RunStage};
use anyhow::{bail, Result};

/// What `train` did: stage 1, stage 2, or both (`--stage all`, stage 1 absent when it was
/// already done).
#[derive(Clone, Debug, Default)]
pub struct TrainOutcome {
    pub stage1: Option<Trained<PlenoxelsMetrics>>,
    pub stage2: Option<Trained<SurfaceMetrics>>,
}

/// Train the stage(s) `opts` ask for on the Vulkan device `gpu` (`None`: the CPU twins).
pub fn train(opts: &TrainOptions, gpu: Option<&Gpu>) -> Result<TrainOutcome> {
    opts.check_stage_flags()?;
    Ok(match opts.stage {
        Stage::Plenoxels => TrainOutcome {
            stage1: Some(train_plenoxels::train_plenoxels(
                opts,
                &load_data(opts)?,
                gpu,
            )?),
            stage2: None,
        },
        Stage::Surface => TrainOutcome {
            stage1: None,
            stage2: Some(train_surface::train_surface(opts, &load_data(opts)?, gpu)?),
        },
        Stage::All => train_all(opts, gpu)?,
    })
}

/// `--stage all`: a parent run holding stage 1 in `plenoxels/` and stage 2 in `surface/`. With
/// `--resume` it continues whichever stage was interrupted: stage 1 (then stage 2 from scratch),
/// or stage 2 once stage 1 is done. Extending a finished stage 1 (`--iters`) under an existing
/// stage 2 is refused: that stage 2 was built on the old grid.
pub fn train_all(opts: &TrainOptions, gpu: Option<&Gpu>) -> Result<TrainOutcome> {
    let mut parent = RunDir::claim(&opts.out, RunStage::All, opts.open_mode(), &[&opts.data])?;
    let data = load_data(opts)?;
    if opts.resume {
        check_resumed_data(opts, &data.data)?;
    }
    parent.write_info(&run_info(opts, &data.data, None)?)?;
    let s1_dir = parent.file(ALL_STAGE1);
    let s2_dir = parent.file(ALL_STAGE2);
    let s1_ckpt = crate::checkpoint::path::<crate::plenoxel::PlenoxelsStage>(&s1_dir);
    let s2_ckpt = crate::checkpoint::path::<crate::surface::SurfaceStage>(&s2_dir);
    let stage1_opts = TrainOptions {
        stage: Stage::Plenoxels,
        out: s1_dir.clone(),
        resume: opts.resume && s1_ckpt.exists(),
        overwrite: opts.resume && !s1_ckpt.exists(),
        category: None,
        set: Vec::new(),
        alpha_init_scale: None,
        surface_iters: None,
        ..opts.clone()
    };
    let stage2_opts = TrainOptions {
        stage: Stage::Surface,
        out: s2_dir.clone(),
        init: Some(s1_dir.clone()),
        iters: opts.surface_iters,
        res: None,
        resume: opts.resume && s2_ckpt.exists(),
        overwrite: opts.resume && !s2_ckpt.exists(),
        surface_iters: None,
        ..opts.clone()
    };
    let stage1 = if opts.resume && s2_ckpt.exists() {
        let s1 = crate::checkpoint::format::load(&s1_ckpt)?;
        let step = s1.meta["step"].as_u64().unwrap_or(0);
        if opts.iters.is_some_and(|n| n as u64 > step) {
            bail!(
                "--resume --iters {}: stage 1 ({}) finished at step {step} and stage 2 ({}) was \
                 built on that grid; extending stage 1 would leave stage 2 stale. Extend stage 1 \
                 alone (train --stage plenoxels --resume --iters N --out {}), then restart stage \
                 2 (train --stage surface --init {} --out {} --overwrite)",
                opts.iters.unwrap_or(0),
                s1_dir.display(),
                s2_dir.display(),
                s1_dir.display(),
                s1_dir.display(),
                s2_dir.display()
            );
        }
        eprintln!("--stage all --resume: stage 1 is done; resuming stage 2");
        None
    } else {
        Some(train_plenoxels::train_plenoxels(&stage1_opts, &data, gpu)?)
    };
    Ok(TrainOutcome {
        stage1,
        stage2: Some(train_surface::train_surface(&stage2_opts, &data, gpu)?),
    })
}
