//! The two training stages as one contract: a [`Stage`] names its grid, step parameters, step
//! figures and optimiser state and how a checkpoint stores them; a [`StageBackend`] holds a
//! stage's grid on the Vulkan device or on the host and steps it. The training loop
//! (`train::steps`) and the checkpoints (`checkpoint`) are written once over them; the stages are
//! `plenoxel::PlenoxelsStage` (stage 1) and `surface::SurfaceStage` (stage 2). What the backends
//! of one kind share whatever their stage, their background and the figures of the steps not yet
//! taken, is a [`StepStore`] ([`store`]); a Vulkan backend's [`StageBackend`] is written once
//! over [`QueuedBackend`], with its queue and grid buffers in a [`QueuedGrid`] ([`queued`]).

pub mod queued;
pub mod store;

pub use queued::{QueuedBackend, QueuedGrid};
pub use store::{HostRays, HostSteps, StepStore};

use crate::abi::buffers::Background;
use crate::data::TrainViews;
use crate::gpu::{StepTiming, TrainRays};
use crate::grid::SparseArrays;
use crate::math::background_msi::SphereTable;
use anyhow::{anyhow, Result};
use std::path::Path;

/// What a checkpoint of a stage holds, read back.
pub struct Saved<S: Stage> {
    pub grid: S::Grid,
    /// The optimiser's running averages, in the order of [`Stage::STATE_NAMES`].
    pub state: S::State,
    /// The background's spheres ([`Stage::TRAINS_SPHERES`] says whether they are learned).
    pub spheres: Option<SphereTable>,
    pub meta: serde_json::Value,
}

/// One training stage.
pub trait Stage: 'static {
    /// The stage's name in checkpoints, metrics, logs and on the command line.
    const NAME: &'static str;
    /// File name of the stage's checkpoint inside a run directory.
    const CHECKPOINT: &'static str;
    /// Whether the stage trains a background's spheres (stage 1) or keeps them (stage 2).
    const TRAINS_SPHERES: bool;
    /// Names of the optimiser's running averages, as a checkpoint stores them.
    const STATE_NAMES: &'static [&'static str];
    /// Header line of the per-step training log ([`Stage::log_row`]'s columns).
    const LOG_HEADER: &'static str;
    /// The trained grid.
    type Grid: SparseArrays + Send + 'static;
    /// Everything one training step needs besides the rays.
    type Params;
    /// What a training step reports back.
    type Stats: Copy;
    /// The step counters summed over a run, then per training ray.
    type PerRay: Default + Clone;
    /// The optimiser's running averages, one array per name of [`Stage::STATE_NAMES`].
    type State: StateArrays;

    /// Mean squared error of a step's batch.
    fn mse(stats: &Self::Stats) -> f64;
    /// Where a step's figures keep its timing (set by the backend that ran it).
    fn timing(stats: &mut Self::Stats) -> &mut StepTiming;
    /// The step's loss figures, when one of them is not finite (named with their values).
    fn non_finite(stats: &Self::Stats) -> Option<String>;
    /// The log row of a step (`step` = steps done, `elapsed` = seconds since training started).
    fn log_row(stats: &Self::Stats, step: u32, elapsed: f64) -> String;
    /// Add a step's counters to a run's sum.
    fn tally(totals: &mut Self::PerRay, stats: &Self::Stats);
    /// A run's sum of counters scaled by `f` (1 / training rays: per ray).
    fn scaled(totals: &Self::PerRay, f: f64) -> Self::PerRay;
    /// Refuse training views the stage cannot draw its batches from (none by default).
    fn check_views(_views: &TrainViews) -> Result<()> {
        Ok(())
    }

    /// Write a checkpoint atomically with the named optimiser arrays, refusing non-finite values
    /// (the previous file stays).
    fn save(
        path: &Path,
        grid: &Self::Grid,
        optim: &[(&str, &[f32])],
        meta: &serde_json::Value,
    ) -> Result<()>;
    /// Read and validate a checkpoint written by [`Stage::save`].
    fn load(path: &Path) -> Result<Saved<Self>>
    where
        Self: Sized;
}

/// An optimiser state of a fixed number of arrays.
pub trait StateArrays: Sized + Send + 'static {
    /// The arrays, borrowed, in order.
    fn arrays(&self) -> Vec<&[f32]>;
    /// From arrays in order (an error when their number differs).
    fn from_arrays(arrays: Vec<Vec<f32>>) -> Result<Self>;
}

impl<const N: usize> StateArrays for [Vec<f32>; N] {
    fn arrays(&self) -> Vec<&[f32]> {
        self.iter().map(|v| v.as_slice()).collect()
    }

    fn from_arrays(arrays: Vec<Vec<f32>>) -> Result<Self> {
        arrays
            .try_into()
            .map_err(|a: Vec<Vec<f32>>| anyhow!("{} optimiser arrays, expected {N}", a.len()))
    }
}

/// What [`StageBackend::with_state`] calls: the grid and the running averages.
pub type StateFn<'a, S> = dyn FnMut(&<S as Stage>::Grid, &[&[f32]]) -> Result<()> + 'a;

/// A compute backend of stage `S` holding its grid and optimiser state: the GLSL kernels on the
/// Vulkan device, or their CPU twins. A backend submits steps; what it shares with the other
/// stage's backend of its kind (background, figures) sits in its [`StepStore`].
pub trait StageBackend<S: Stage> {
    /// The background and the figures of the steps not yet taken.
    fn store(&self) -> &dyn StepStore<S::Stats>;
    fn store_mut(&mut self) -> &mut dyn StepStore<S::Stats>;
    /// One optimisation step on `src`'s rays: the CPU backend runs it (drawing a sampled batch
    /// on the host); the Vulkan backend records it, drawing a sampled batch on the device from
    /// views it uploads once, and returns once it is submitted (the device may still run it).
    /// Its figures come with [`Self::take_stats`].
    fn submit(&mut self, src: TrainRays, p: &S::Params) -> Result<()>;
    /// The current grid.
    fn grid(&self) -> Result<S::Grid>;
    /// The optimiser's running averages.
    fn optimizer_state(&self) -> Result<S::State>;
    /// Bytes of a copy of the grid and the running averages (what a checkpoint holds).
    fn state_bytes(&self) -> u64;
    /// Call `f` with the grid and the running averages: borrowed where the backend holds them
    /// in host memory (checkpoints of large grids copy nothing), else downloaded.
    fn with_state(&self, f: &mut StateFn<S>) -> Result<()> {
        let state = self.optimizer_state()?;
        f(&self.grid()?, &state.arrays())
    }
    /// Replace grid and optimiser state (after resampling or pruning); the background stays.
    fn load(&mut self, grid: S::Grid, state: Option<S::State>) -> Result<()>;
    /// Replace the optimiser state of the grid the backend holds (when resuming: the backend
    /// was built on the checkpoint's grid); an error when its arrays do not match the grid.
    fn load_state(&mut self, state: S::State) -> Result<()>;

    /// Backend name for logs ("vulkan" or "cpu").
    fn name(&self) -> &'static str {
        self.store().kind()
    }
    /// One optimisation step on a batch, waited for: `rays` 6 floats per ray, `targets` 3 per
    /// ray. The figures of earlier steps not yet taken stay for [`Self::take_stats`].
    fn step(&mut self, rays: &[f32], targets: &[f32], p: &S::Params) -> Result<S::Stats> {
        self.submit(TrainRays::Host { rays, targets }, p)?;
        self.store_mut().last()
    }
    /// One optimisation step on the batch of `n` rays drawn from `views` with `seed`
    /// (`data::TrainViews::sample`), submitted as [`Self::submit`] says.
    fn step_sampled(
        &mut self,
        views: &TrainViews,
        seed: u64,
        n: usize,
        p: &S::Params,
    ) -> Result<()> {
        S::check_views(views)?;
        self.submit(views.train_rays(seed, n), p)
    }
    /// The figures of every submitted step since the last call, in order (waits for the steps
    /// still running). A Vulkan backend keeps at most [`crate::gpu::STEP_SLOTS`] steps' figures
    /// on the device and reads them into host memory when that many have not been taken.
    fn take_stats(&mut self) -> Result<Vec<S::Stats>> {
        self.store_mut().take()
    }
    /// The background with its optimiser state (white and fixed unless set).
    fn background(&self) -> Result<Background> {
        self.store().background()
    }
    /// Replace the background (colour, whether it is learned, its optimiser state).
    fn set_background(&mut self, bg: Background) -> Result<()> {
        self.store_mut().set_background(bg)
    }
    /// The background's spheres with their optimiser state (`None`: the colour alone).
    fn spheres(&self) -> Result<Option<SphereTable>> {
        self.store().spheres()
    }
    /// Replace them (learned when their shape says so; stage 2 never steps them).
    fn set_spheres(&mut self, spheres: Option<SphereTable>) -> Result<()> {
        self.store_mut().set_spheres(spheres)
    }
}

/// PSNR in dB of a mean squared error on [0, 1] colours.
pub fn psnr(mse: f64) -> f64 {
    -10.0 * mse.max(1e-20).log10()
}
