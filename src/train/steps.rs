//! The training loop of both stages: batches of training rays drawn per step from a seed, one
//! backend step each, the figures read in groups (training log, progress, NaN/Inf stop),
//! periodic atomic checkpoints written in the background, the stop on a signal after a
//! checkpoint, and at the end the last checkpoint and the test renders. What a stage does
//! besides ([`StageSteps`]): its step parameters, work before a step (stage 1's upsampling),
//! work after the last step (stage 2's pruning) and its renders.

use super::progress::{pair, Progress, StepGroup, Throughput};
use super::render::RenderedSplit;
use crate::checkpoint::writer::{BackgroundSave, Cadence};
use crate::checkpoint::{self, RunCheckpoints};
use crate::data::{Dataset, TrainViews};
use crate::run::interrupt::{self, Interrupted};
use crate::run::train_log;
use crate::stage::{Stage, StageBackend};
use anyhow::{bail, Context, Result};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use serde::Serialize;
use std::io::Write;
use std::path::Path;
use std::time::Instant;

/// Seeded per step, so a resumed run draws the same batches as an uninterrupted one: its first
/// draw seeds the step's ray batch (`data::TrainViews::sample`, a function of that seed alone).
pub(crate) fn step_rng(seed: u64, step: u32) -> Pcg64 {
    Pcg64::seed_from_u64(seed ^ (step as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15))
}

/// The schedule the loop runs: steps, rays per step, the seed of the batches and the
/// checkpoint cadence (every `checkpoint_every` steps, at least `checkpoint_min_seconds` apart).
#[derive(Clone, Copy, Debug)]
pub struct LoopSchedule {
    pub iters: u32,
    pub batch: u32,
    pub seed: u64,
    pub checkpoint_every: u32,
    pub checkpoint_min_seconds: f32,
}

/// A stage configuration's [`LoopSchedule`].
pub trait Scheduled {
    fn schedule(&self) -> LoopSchedule;
}

/// The [`LoopSchedule`] of a stage configuration: its fields of the same names.
macro_rules! loop_schedule {
    ($c:expr) => {
        $crate::train::steps::LoopSchedule {
            iters: $c.iters,
            batch: $c.batch,
            seed: $c.seed,
            checkpoint_every: $c.checkpoint_every,
            checkpoint_min_seconds: $c.checkpoint_min_seconds,
        }
    };
}
pub(crate) use loop_schedule;

/// What a stage does around the shared loop, on backends of type `B`.
pub trait StageSteps<S: Stage, B: StageBackend<S> + ?Sized> {
    /// The configuration each checkpoint records, with the loop's schedule.
    type Config: Serialize + Scheduled;
    fn config(&self) -> &Self::Config;
    /// The parameters of `step`, drawing what it needs from `rng` (after the batch's seed).
    fn params(&mut self, step: u32, rng: &mut Pcg64) -> S::Params;
    /// Render the test split into `out`.
    fn render_test(&mut self, backend: &mut B, data: &Dataset, out: &Path)
        -> Result<RenderedSplit>;

    /// The training views batches are drawn from (uniformly, unless a stage says otherwise).
    fn views<'d>(&self, data: &'d Dataset) -> Result<TrainViews<'d>> {
        TrainViews::new(&data.train, &data.scene)
    }
    /// Before the first step of this process (`start_step`: 0, or the step after a resumed
    /// checkpoint); nothing unless a stage says otherwise.
    fn start(&mut self, _backend: &mut B, _data: &Dataset, _start_step: u32) -> Result<()> {
        Ok(())
    }
    /// Work due before `step` (its time is not the training's); whether there was any (none
    /// unless a stage says otherwise).
    fn before_step(
        &mut self,
        _backend: &mut B,
        _data: &Dataset,
        _step: u32,
        _progress: &mut Progress,
    ) -> Result<bool> {
        Ok(false)
    }
    /// Whether [`Self::before_step`] has work before `step` (the figures are read before it).
    fn work_before(&self, _step: u32) -> bool {
        false
    }
    /// After the last step, before the last checkpoint; nothing unless a stage says otherwise.
    fn finish(&mut self, _backend: &mut B) -> Result<()> {
        Ok(())
    }
}

/// Wall time per phase and throughput of a finished run.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct LoopReport<P> {
    pub steps: u32,
    pub train_seconds: f64,
    pub checkpoint_seconds: f64,
    pub render_seconds: f64,
    /// Training rays per second over the steps after the first 10 (warm-up: pipeline compiles).
    pub train_rays_per_s: f64,
    pub final_mse: f64,
    pub test_psnr: f64,
    /// The step counters per training ray.
    pub per_ray: P,
}

/// Train from `start_step` (0, or the step after a resumed checkpoint) to the schedule's last
/// step with `stage`'s hooks, writing `out`'s checkpoint (`S::CHECKPOINT`) and training log
/// (`run::dir::TRAIN_LOG`, header `S::LOG_HEADER`; a resumed run cuts it back to the
/// checkpoint's step), then render the test split into `out/test/`.
pub fn run<S, B, T>(
    backend: &mut B,
    stage: &mut T,
    data: &Dataset,
    out: &Path,
    start_step: u32,
    show_progress: bool,
) -> Result<(LoopReport<S::PerRay>, RenderedSplit)>
where
    S: Stage,
    B: StageBackend<S> + ?Sized,
    T: StageSteps<S, B>,
{
    std::fs::create_dir_all(out)
        .with_context(|| format!("creating run directory {}", out.display()))?;
    let _catch = interrupt::catch();
    let sched = stage.config().schedule();
    let ck = RunCheckpoints {
        path: checkpoint::path::<S>(out),
        config: serde_json::to_value(stage.config()).context("recording the configuration")?,
        mode: data.background,
    };
    let log_path = out.join(crate::run::dir::TRAIN_LOG);
    let mut log = train_log::open(&log_path, S::LOG_HEADER, start_step)?;
    let mut report = LoopReport::<S::PerRay>::default();
    let mut progress = Progress::new(sched.iters as u64, start_step as u64, show_progress);
    let mut throughput = Throughput::new(start_step);
    let mut totals = S::PerRay::default();
    let mut mse = f64::NAN;
    let views = stage.views(data)?;
    let t_start = Instant::now();
    stage.start(backend, data, start_step)?;
    let mut group = StepGroup::default();
    let mut writer = BackgroundSave::default();
    let mut cadence = Cadence::new(sched.checkpoint_every, sched.checkpoint_min_seconds);
    for step in start_step..sched.iters {
        if stage.before_step(backend, data, step, &mut progress)? {
            group.restart();
        }
        let mut rng = step_rng(sched.seed, step);
        let batch_seed: u64 = rng.random();
        let p = stage.params(step, &mut rng);
        backend.step_sampled(&views, batch_seed, sched.batch as usize, &p)?;
        group.push(step);
        // A signal asked for a stop: this step's checkpoint, then out (after the last step the
        // run ends anyway).
        let stop = interrupt::requested().filter(|_| step + 1 < sched.iters);
        let checkpoint = cadence.due(step, sched.iters) || stop.is_some();
        // Read the group before other work, so that its wall time is the training's alone.
        let read_now = checkpoint || stage.work_before(step + 1);
        if group.due(step, sched.iters, read_now) {
            let (steps, secs) = group.take();
            let n = steps.len();
            let before = t_start.elapsed().as_secs_f64() - secs;
            for (i, (s, stats)) in pair(steps, backend.take_stats()?)?.into_iter().enumerate() {
                if let Some(figures) = S::non_finite(&stats) {
                    bail!(
                        "non-finite loss at step {s} ({figures}); the last good checkpoint is {}",
                        ck.path.display()
                    );
                }
                mse = S::mse(&stats);
                throughput.add(s, sched.batch as usize, secs / n as f64);
                S::tally(&mut totals, &stats);
                // The group's wall time, spread evenly over its steps.
                let elapsed = before + secs * (i + 1) as f64 / n as f64;
                writeln!(log, "{}", S::log_row(&stats, s + 1, elapsed))
                    .with_context(|| format!("writing {}", log_path.display()))?;
            }
            progress.step(step as u64 + 1, mse, throughput.rays_per_s());
            report.train_seconds += secs;
        }
        stop_on_failed_checkpoint(&mut writer, step, &ck.path)?;
        if checkpoint {
            let t = Instant::now();
            train_log::flush(&mut log, &log_path)?;
            ck.write(&mut writer, backend, step + 1)?;
            report.checkpoint_seconds += t.elapsed().as_secs_f64();
            group.restart();
        }
        if let Some(signal) = stop {
            progress.finish();
            let (done, path) = (step + 1, ck.path.clone());
            let written = writer.finish();
            return Err(Interrupted::after_checkpoint(
                signal,
                done,
                sched.iters,
                path,
                written,
            ));
        }
    }
    progress.finish();
    train_log::flush(&mut log, &log_path)?;
    drop(log);
    writer.finish()?;
    stage.finish(backend)?;
    // The last checkpoint is written while the test views render.
    let t = Instant::now();
    ck.write(&mut writer, backend, sched.iters)?;
    report.checkpoint_seconds += t.elapsed().as_secs_f64();

    let t = Instant::now();
    let rendered = stage.render_test(backend, data, &out.join("test"))?;
    report.render_seconds = t.elapsed().as_secs_f64();
    let t = Instant::now();
    writer.finish()?;
    report.checkpoint_seconds += t.elapsed().as_secs_f64();
    report.steps = sched.iters;
    report.train_rays_per_s = throughput.run_rays_per_s();
    report.final_mse = mse;
    report.test_psnr = rendered.mean_psnr;
    report.per_ray = S::scaled(&totals, 1.0 / throughput.rays().max(1) as f64);
    Ok((report, rendered))
}

/// The error of a periodic checkpoint that failed to be written, as soon as its thread ends:
/// the run stops after `step` rather than train on without one.
fn stop_on_failed_checkpoint(writer: &mut BackgroundSave, step: u32, path: &Path) -> Result<()> {
    writer.check().with_context(|| {
        format!(
            "a checkpoint of this run could not be written; training stopped after step {} \
             rather than go on without one ({} keeps the last one written, if any)",
            step + 1,
            path.display()
        )
    })
}
