//! What both training stages share: the dataset as loaded for training, a run's `run.json`, how a
//! training call ended, resuming from a checkpoint, and the `metrics.json` of a finished run.

use super::metrics::{SurfaceSeconds, TrainMetrics};
use super::train_options::TrainOptions;
use crate::checkpoint::{self, BackgroundRecord, Recorded};
use crate::data::dataset::peak_rss_bytes;
use crate::data::ndc::Space;
use crate::data::{Aabb, BackgroundMode, Dataset, LoadOptions, SceneBox};
use crate::gpu::Gpu;
use crate::run::identity::DataIdentity;
use crate::run::same_data::check_same_data;
use crate::run::{RunDir, RunInfo, RunStage};
use crate::stage::{Stage, StageBackend};
use crate::train::steps::LoopReport;
use crate::train::RenderedSplit;
use anyhow::{bail, ensure, Context, Result};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// A dataset loaded for training, and the seconds its loading took.
pub struct Loaded {
    pub data: Dataset,
    pub seconds: f64,
}

/// The dataset `--data` names, at `--downscale`, composited on `--background`, in the scene box
/// [`scene_box`] picks; `inspect`'s warnings are repeated on stderr.
pub fn load_data(opts: &TrainOptions) -> Result<Loaded> {
    let t = Instant::now();
    let recorded = recorded_run(opts);
    let background = match (opts.background, &recorded) {
        (BackgroundMode::Auto, Some(info)) => info.background,
        (asked, _) => asked,
    };
    let data = Dataset::load(
        &opts.data,
        &LoadOptions {
            downscale: opts.downscale,
            background,
            scene: scene_box(opts, recorded.as_ref())?,
            space: opts.space,
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

/// The `run.json` of the run being resumed, or of the stage-1 run `--init` names (a checkpoint
/// file's run is the directory that holds it); `None` when there is none.
fn recorded_run(opts: &TrainOptions) -> Option<RunInfo> {
    let recorded_in = |dir: &Path| -> Option<RunInfo> {
        dir.join(crate::run::dir::MARKER)
            .is_file()
            .then(|| crate::run::read_info(dir).ok())
            .flatten()
    };
    match (opts.resume, opts.init.as_deref()) {
        (true, _) => recorded_in(&opts.out),
        (false, Some(init)) if init.is_dir() => recorded_in(init),
        (false, Some(init)) => init.parent().and_then(recorded_in),
        _ => None,
    }
}

/// The scene box to train in, when not the dataset's own: `--box`; else, resuming, the one the
/// run recorded; else, for stage 2 from a stage-1 run directory (or a checkpoint in one), the
/// one that run recorded (a grid is only valid in the box or NDC space it was trained in).
/// `--box` on a run that recorded another box, and `--space box|ndc` on a run trained in the
/// other space, are refused.
fn scene_box(opts: &TrainOptions, recorded: Option<&RunInfo>) -> Result<Option<SceneBox>> {
    let given = opts
        .scene_box
        .as_deref()
        .map(|v| Aabb::from_values("--box", v))
        .transpose()?;
    ensure!(
        given.is_none() || opts.space != Space::Ndc,
        "--box and --space ndc: a box is a grid in dataset units, NDC one over the mean \
         camera's view; give one of them"
    );
    let recorded = recorded.and_then(|i| i.scene());
    let source = || {
        if opts.resume {
            opts.out.display()
        } else {
            opts.init.as_deref().unwrap_or(&opts.out).display()
        }
    };
    let recorded_ndc = recorded.map(|r| r.1.ndc.is_some());
    let clash = match (opts.space, recorded_ndc) {
        (Space::Box, Some(true)) => Some("NDC"),
        (Space::Ndc, Some(false)) => Some("a box"),
        _ => None,
    };
    if let Some(was) = clash {
        bail!(
            "--space {}: {} was trained in {was}, and a grid is only valid in the space it was \
             trained in; leave --space out",
            if opts.space == Space::Box {
                "box"
            } else {
                "ndc"
            },
            source()
        );
    }
    if let (Some(g), Some((None, _))) = (given, recorded) {
        bail!(
            "--box {g}: {} was trained in NDC (a forward-facing capture), not in a box; leave \
             --box out",
            source()
        );
    }
    if let (Some(g), Some((Some(r), _))) = (given, recorded) {
        // The recorded box is the grid's cube: --box must give that cube.
        let cube = Aabb::of_scene(&g.scene_box());
        let close = (cube.lo() - r.lo())
            .abs()
            .max(cube.hi() - r.hi())
            .max_element()
            <= 1e-4 * (r.hi() - r.lo()).max_element();
        ensure!(
            close,
            "--box {g}: the grid it needs ({cube}) is not the one {} was trained in ({r}); leave \
             --box out to use that one",
            source()
        );
    }
    Ok(recorded.map(|r| r.1).or(given.map(|g| g.scene_box())))
}

/// The `run.json` of a training run: the dataset's absolute path and identity, the downscale
/// factor, the background, the scene box's scale and cube and (stage 2) the grid it started from.
pub fn run_info(opts: &TrainOptions, data: &Dataset, init: Option<PathBuf>) -> Result<RunInfo> {
    Ok(RunInfo {
        stage: None,
        data: std::fs::canonicalize(&opts.data)
            .with_context(|| format!("dataset {}", opts.data.display()))?,
        downscale: opts.downscale,
        background: data.background,
        scene_scale: Some(data.scene.scale),
        scene_box: data
            .scene
            .ndc
            .is_none()
            .then(|| Aabb::of_scene(&data.scene)),
        ndc: data.scene.ndc,
        identity: Some(DataIdentity::of(data)),
        init,
        imported_from: None,
    })
}

/// `--resume`: refuse to continue the run in `opts.out` on another dataset than its own (see
/// [`crate::run::identity`]); call before its `run.json` is rewritten.
pub fn check_resumed_data(opts: &TrainOptions, data: &Dataset) -> Result<()> {
    let recorded = crate::run::read_info(&opts.out)?;
    let now = run_info(opts, data, None)?;
    check_same_data(
        "--resume",
        &opts.out,
        &recorded,
        &now,
        opts.allow_other_data,
    )
}

/// Claim `opts.out` for a `stage` run on `inputs` (`RunDir::claim`); resuming, refuse a run
/// trained on another dataset than `data` ([`check_resumed_data`]).
pub(super) fn claim(
    opts: &TrainOptions,
    stage: RunStage,
    inputs: &[&Path],
    data: &Dataset,
) -> Result<RunDir> {
    let run = RunDir::claim(&opts.out, stage, opts.open_mode(), inputs)?;
    if opts.resume {
        check_resumed_data(opts, data)?;
    }
    Ok(run)
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

/// A run restored from its checkpoint: the backend, the configuration and the next step.
pub(super) type Resumed<B, C> = (Box<B>, C, u32);

/// Resumes the stage-`S` run in `opts.out` from its checkpoint: `make` builds the backend for
/// the checkpoint's grid, which is then restored (optimiser state, background, step); the
/// configuration must pass `check_flags` and the background match `--background`. `iters` (when
/// given) replaces the configuration's step count. Returns
/// `Ok((backend, configuration, step))`, or `Err(Trained::AlreadyDone)` when the run is already
/// at its last step.
pub(super) fn resume<S, C, B, M>(
    opts: &TrainOptions,
    iters: Option<u32>,
    make: impl FnOnce(S::Grid) -> Result<Box<B>>,
    check_flags: impl FnOnce(&C) -> Result<()>,
) -> Result<Result<Resumed<B, C>, Trained<M>>>
where
    S: Stage,
    C: Recorded,
    B: StageBackend<S> + ?Sized,
{
    let ckpt = checkpoint::path::<S>(&opts.out);
    ensure!(
        ckpt.exists(),
        "--resume: no checkpoint at {}",
        ckpt.display()
    );
    let (backend, step, mut cfg, bg) = checkpoint::resume::<S, C, B>(make, &ckpt)?;
    check_flags(&cfg)?;
    bg.ensure_mode(opts.background, "the checkpoint")?;
    let total = cfg.iters_mut();
    if let Some(n) = iters {
        *total = n; // extend (or shorten) the run; the schedules keep their lengths
    }
    if step >= *total {
        return Ok(Err(Trained::AlreadyDone {
            checkpoint: ckpt,
            step,
            total: *total,
        }));
    }
    eprintln!("resuming {} at step {step} of {}", ckpt.display(), total);
    Ok(Ok((backend, cfg, step)))
}

/// On `--resume` the checkpoint's configuration wins: refuse the flags that ask for something
/// else rather than ignoring them. `clashes` names each flag and whether it asks for another
/// value; `kept` describes the checkpoint's configuration, `steps` the flags that may change it.
pub(super) fn refuse_clashes(clashes: &[(&str, bool)], kept: &str, steps: &str) -> Result<()> {
    let named: Vec<&str> = clashes.iter().filter(|c| c.1).map(|c| c.0).collect();
    ensure!(
        named.is_empty(),
        "--resume continues the checkpoint's configuration ({kept}); {} cannot change it (only \
         {steps} can)",
        named.join(", ")
    );
    Ok(())
}

/// Who trained a run and since when: what both stages' `metrics.json` record of it besides its
/// figures.
pub(super) struct Trainer {
    stage: RunStage,
    backend: &'static str,
    device: Option<String>,
    background: BackgroundRecord,
    /// Seconds reading the dataset, and when the training call started.
    load: f64,
    started: Instant,
}

impl Trainer {
    /// A `stage` run trained by `backend` on `gpu` (`None`: the CPU twins) on `data` (loaded in
    /// `load` seconds) by a call that started at `started`, with the background as `backend`
    /// holds it now.
    pub(super) fn of<S: Stage, B: StageBackend<S> + ?Sized>(
        stage: RunStage,
        backend: &B,
        gpu: Option<&Gpu>,
        data: &Dataset,
        (load, started): (f64, Instant),
    ) -> Result<Self> {
        Ok(Trainer {
            stage,
            backend: backend.name(),
            device: gpu.map(|g| g.info().name.clone()),
            background: BackgroundRecord::of(
                data.background,
                &backend.background()?,
                backend.spheres()?.as_ref(),
            ),
            load,
            started,
        })
    }

    /// Write the `metrics.json` of the finished run into `run`: the loop's `report` and the test
    /// renders, with the stage's wall time per phase (`seconds` of the phases both stages have),
    /// its own figures and its configuration.
    pub(super) fn finish<W: Serialize, X: Serialize, C: Serialize, P>(
        self,
        run: &RunDir,
        (report, rendered): (&LoopReport<P>, RenderedSplit),
        seconds: impl FnOnce(SurfaceSeconds) -> W,
        figures: X,
        config: C,
    ) -> Result<Trained<TrainMetrics<W, X, C>>> {
        let wall_seconds = seconds(SurfaceSeconds {
            load: self.load,
            train: report.train_seconds,
            checkpoint: report.checkpoint_seconds,
            render_test: report.render_seconds,
            total: self.load + self.started.elapsed().as_secs_f64(),
        });
        let metrics = TrainMetrics {
            stage: self.stage.name().into(),
            backend: self.backend.into(),
            device: self.device,
            wall_seconds,
            train_rays_per_s: report.train_rays_per_s,
            final_train_mse: report.final_mse,
            test_psnr: report.test_psnr,
            test_psnr_per_view: rendered.psnr,
            figures,
            peak_rss_bytes: peak_rss_bytes(),
            background: self.background,
            config,
        };
        run.write_metrics(&metrics)?;
        Ok(Trained::Done(metrics))
    }
}
