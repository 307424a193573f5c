//! `train` as library calls: the dataset load shared by the stages, [`train`] for the stage the
//! options ask for, and `--stage all` ([`train_all`]): a parent run holding stage 1 in
//! `plenoxels/` and stage 2 in `surface/`.

use super::metrics::{Stage1Metrics, Stage2Metrics};
use super::train_options::{Stage, TrainOptions};
use super::{train_stage1, train_stage2};
use crate::data::{Dataset, LoadOptions};
use crate::gpu::Gpu;
use crate::run::dir::{ALL_STAGE1, ALL_STAGE2};
use crate::run::{RunDir, RunInfo, RunStage};
use crate::train::Category;
use anyhow::{bail, ensure, Context, Result};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// A dataset loaded for training, and the seconds its loading took.
pub struct Loaded {
    pub data: Dataset,
    pub seconds: f64,
}

/// The dataset `--data` names, at `--downscale`; `inspect`'s warnings are repeated on stderr.
pub fn load_data(opts: &TrainOptions) -> Result<Loaded> {
    let t = Instant::now();
    let data = Dataset::load(
        &opts.data,
        &LoadOptions {
            downscale: opts.downscale,
            ..Default::default()
        },
    )?;
    for w in crate::data::inspect::inspect(&data).warnings {
        eprintln!("warning: {}: {w}", opts.data.display());
    }
    Ok(Loaded {
        data,
        seconds: t.elapsed().as_secs_f64(),
    })
}

/// The `run.json` of a training run: the dataset's absolute path, the downscale factor, the
/// scene box's scale and (stage 2) the grid it started from.
pub fn run_info(opts: &TrainOptions, data: &Dataset, init: Option<PathBuf>) -> Result<RunInfo> {
    Ok(RunInfo {
        stage: None,
        data: std::fs::canonicalize(&opts.data)
            .with_context(|| format!("dataset {}", opts.data.display()))?,
        downscale: opts.downscale,
        scene_scale: Some(data.scene.scale),
        init,
        imported_from: None,
    })
}

/// How a training call ended.
#[derive(Clone, Debug)]
pub enum Trained<M> {
    /// The run trained to its last step and wrote these metrics.
    Done(M),
    /// `--resume` found the run already at its last step: nothing was trained.
    AlreadyDone {
        checkpoint: PathBuf,
        step: u32,
        total: u32,
    },
}

/// What `train` did: stage 1, stage 2, or both (`--stage all`, stage 1 absent when it was
/// already done).
#[derive(Clone, Debug, Default)]
pub struct TrainOutcome {
    pub stage1: Option<Trained<Stage1Metrics>>,
    pub stage2: Option<Trained<Stage2Metrics>>,
}

/// Train the stage(s) `opts` ask for on the Vulkan device `gpu` (`None`: the CPU twins).
pub fn train(opts: &TrainOptions, gpu: Option<&Gpu>) -> Result<TrainOutcome> {
    opts.check_stage_flags()?;
    Ok(match opts.stage {
        Stage::Plenoxels => TrainOutcome {
            stage1: Some(train_stage1::train_stage1(opts, &load_data(opts)?, gpu)?),
            stage2: None,
        },
        Stage::Surface => TrainOutcome {
            stage1: None,
            stage2: Some(train_stage2::train_stage2(opts, &load_data(opts)?, gpu)?),
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
    parent.write_info(&run_info(opts, &data.data, None)?)?;
    let s1_dir = parent.file(ALL_STAGE1);
    let s2_dir = parent.file(ALL_STAGE2);
    let s1_ckpt = crate::train::stage1::checkpoint_path(&s1_dir);
    let s2_ckpt = crate::train::stage2::checkpoint_path(&s2_dir);
    let stage1_opts = TrainOptions {
        stage: Stage::Plenoxels,
        out: s1_dir.clone(),
        resume: opts.resume && s1_ckpt.exists(),
        overwrite: opts.resume && !s1_ckpt.exists(),
        category: Category::Thin,
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
        let s1 = crate::grid::checkpoint::load(&s1_ckpt)?;
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
        Some(train_stage1::train_stage1(&stage1_opts, &data, gpu)?)
    };
    Ok(TrainOutcome {
        stage1,
        stage2: Some(train_stage2::train_stage2(&stage2_opts, &data, gpu)?),
    })
}

/// Resumes the run whose checkpoint is `ckpt`: `restore` builds the backend from it and returns
/// `(backend, step reached, configuration)`; `iters` (when given) replaces the step count that
/// `total` points at in the configuration. Returns `Ok((backend, configuration, step))`, or
/// `Err(Trained::AlreadyDone)` when the run is already at its last step.
pub(super) fn resume<B, C, M>(
    ckpt: &Path,
    iters: Option<u32>,
    total: impl FnOnce(&mut C) -> &mut u32,
    restore: impl FnOnce() -> Result<(B, u32, C)>,
) -> Result<Result<(B, C, u32), Trained<M>>> {
    ensure!(
        ckpt.exists(),
        "--resume: no checkpoint at {}",
        ckpt.display()
    );
    let (backend, step, mut cfg) = restore()?;
    let total = total(&mut cfg);
    if let Some(n) = iters {
        *total = n; // extend (or shorten) the run; the schedules keep their lengths
    }
    if step >= *total {
        return Ok(Err(Trained::AlreadyDone {
            checkpoint: ckpt.to_path_buf(),
            step,
            total: *total,
        }));
    }
    eprintln!("resuming {} at step {step} of {}", ckpt.display(), total);
    Ok(Ok((backend, cfg, step)))
}
