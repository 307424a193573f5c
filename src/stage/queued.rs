//! What both stages' Vulkan backends do alike, written once: a Vulkan backend holds its
//! [`StepQueue`] and its grid's [`GridBuffers`] in a [`QueuedGrid`], and names how a training
//! step starts its batch, plans and records its passes and copies its figures
//! ([`QueuedBackend`]); its [`StageBackend`] follows (submission, the reads that wait for the
//! steps in flight, the rebuild that keeps the background, views and figures), and so does the
//! run of a plan on host rays that a backend's `gradients` waits for.

use super::{Stage, StageBackend, StateArrays, StepStore};
use crate::abi::buffers::Background;
use crate::gpu::{
    Batch, BatchRays, Gpu, GridBuffers, Phase, PhaseClock, SlotFigures, StepQueue, StepTiming,
    TrainRays,
};
use crate::grid::SparseArrays;
use crate::math::background_msi::SphereTable;
use anyhow::{ensure, Result};

/// What a Vulkan backend of stage `S` holds whatever its stage: the queue of its steps, and its
/// grid as placement and the buffers of its links and optimised arrays.
pub struct QueuedGrid<S: Stage> {
    /// The steps in flight, their figures, the ray buffers, the training views and the
    /// background. First, so that dropping waits for the steps before any buffer they use is
    /// freed (a backend holds its `QueuedGrid` as its first field for the same reason).
    pub queue: StepQueue<S::Stats>,
    /// The links and the optimised arrays, in the order of [`Stage::STATE_NAMES`], with their
    /// gradients and running averages.
    pub bufs: GridBuffers,
    /// The grid without its links and arrays (resolution, placement, …).
    pub meta: S::Grid,
}

impl<S: Stage> QueuedGrid<S>
where
    S::Stats: SlotFigures,
{
    /// `grid` on `gpu`, with zero optimiser state and a queue whose step record is `step` (u32
    /// words), whose batches output `out_bytes` per ray and whose readback slots hold `parts`
    /// (bytes each).
    pub fn new(
        gpu: &Gpu,
        grid: S::Grid,
        step: &[u32],
        out_bytes: usize,
        parts: &[u64],
    ) -> Result<Self> {
        Ok(QueuedGrid {
            queue: StepQueue::new(gpu, step, out_bytes, parts)?,
            bufs: GridBuffers::new(gpu, grid.links(), grid.rows(), &grid.arrays())?,
            meta: grid.without_arrays(),
        })
    }

    /// The grid, downloaded (no step is in flight).
    pub fn download(&self) -> Result<S::Grid> {
        let (links, arrays) = (self.bufs.download_links()?, self.bufs.download_values()?);
        self.meta.clone().with_arrays(links, arrays)
    }
}

/// The queue's figures, each with its step's timing set.
impl<S: Stage> StepStore<S::Stats> for QueuedGrid<S>
where
    S::Stats: SlotFigures,
{
    fn kind(&self) -> &'static str {
        "vulkan"
    }

    fn take(&mut self) -> Result<Vec<S::Stats>> {
        let taken = self.queue.take()?;
        Ok(taken.into_iter().map(with_timing::<S>).collect())
    }

    fn last(&mut self) -> Result<S::Stats> {
        Ok(with_timing::<S>(self.queue.last()?))
    }

    fn background(&self) -> Result<Background> {
        self.queue.background()
    }

    fn set_background(&mut self, bg: Background) -> Result<()> {
        self.queue.set_background(bg)
    }

    fn spheres(&self) -> Result<Option<SphereTable>> {
        self.queue.spheres()
    }

    fn set_spheres(&mut self, spheres: Option<SphereTable>) -> Result<()> {
        self.queue.set_spheres(spheres)
    }
}

/// A step's figures with `timing` in them.
fn with_timing<S: Stage>((mut stats, timing): (S::Stats, StepTiming)) -> S::Stats {
    *S::timing(&mut stats) = timing;
    stats
}

/// A Vulkan backend of stage `S`: its steps go through the queue of its [`QueuedGrid`], each one
/// batch of the passes of a plan (`plenoxel::plan`, `surface::plan`).
pub trait QueuedBackend<S: Stage>: Sized
where
    S::Stats: SlotFigures,
{
    /// A step's passes, in order.
    type Plan;
    fn core(&self) -> &QueuedGrid<S>;
    fn core_mut(&mut self) -> &mut QueuedGrid<S>;
    /// The plan of a training step of `n` rays (and what it changes on the host counted).
    fn plan_step(&mut self, p: &S::Params, n: usize) -> Result<Self::Plan>;
    /// Start a batch on `src`'s rays: the step reset and the backend's counters cleared (the
    /// uploads charged to `clock`).
    fn begin(&mut self, src: TrainRays, clock: &mut PhaseClock) -> Result<(Batch, BatchRays)>;
    /// Record `plan`'s passes, in order, on the batch of `n` rays at `rays`.
    fn record_plan(
        &self,
        b: &mut Batch,
        plan: &Self::Plan,
        rays: BatchRays,
        n: usize,
    ) -> Result<()>;
    /// After a training step's passes: record copying its figures (`n` rays) into readback
    /// `slot`.
    fn record_figures(&self, b: &mut Batch, slot: usize, n: usize) -> Result<()>;
    /// A backend on the same device for `grid`, with zero optimiser state and a fresh queue.
    fn fresh(&self, grid: S::Grid) -> Result<Self>;

    /// Run `plan` on host rays (`weights`: per-ray importance, `None` for all 1; `n` of them)
    /// and wait for it: the data-term pass of a backend's `gradients`.
    fn run_plan(
        &mut self,
        plan: &Self::Plan,
        rays: &[f32],
        targets: &[f32],
        weights: Option<&[f32]>,
    ) -> Result<()> {
        self.core().queue.settle()?;
        let n = rays.len() / 6;
        ensure!(
            weights.is_none_or(|w| w.len() == n),
            "{} weights for {n} rays",
            weights.map_or(0, |w| w.len())
        );
        let src = TrainRays::Host { rays, targets };
        let (mut b, mut at) = self.begin(src, &mut PhaseClock::start())?;
        let gpu = self.core().queue.gpu();
        let weight_buf = weights.map(|w| gpu.upload(w)).transpose()?;
        if let Some(w) = &weight_buf {
            at.weights = w.address();
        }
        self.record_plan(&mut b, plan, at, n)?;
        b.submit()?;
        Ok(())
    }
}

impl<S: Stage, B: QueuedBackend<S>> StageBackend<S> for B
where
    S::Stats: SlotFigures,
{
    fn store(&self) -> &dyn StepStore<S::Stats> {
        self.core()
    }

    fn store_mut(&mut self) -> &mut dyn StepStore<S::Stats> {
        self.core_mut()
    }

    /// Plan the step, record it on one batch with its figures and submit it without waiting (up
    /// to `MAX_IN_FLIGHT` steps run on the device while the host records the next).
    fn submit(&mut self, src: TrainRays, p: &S::Params) -> Result<()> {
        let n = src.len();
        let mut clock = PhaseClock::start();
        let slot = self.core_mut().queue.slot_for(&src)?;
        let plan = self.plan_step(p, n)?;
        clock.mark(Phase::Record);
        let (mut b, rays) = self.begin(src, &mut clock)?;
        self.record_plan(&mut b, &plan, rays, n)?;
        self.record_figures(&mut b, slot, n)?;
        self.core_mut().queue.submit(b, n, clock)
    }

    fn grid(&self) -> Result<S::Grid> {
        self.core().queue.settle()?;
        self.core().download()
    }

    fn optimizer_state(&self) -> Result<S::State> {
        self.core().queue.settle()?;
        S::State::from_arrays(self.core().bufs.download_states()?)
    }

    fn state_bytes(&self) -> u64 {
        self.core().bufs.state_bytes()
    }

    fn load_state(&mut self, state: S::State) -> Result<()> {
        self.core().queue.settle()?;
        self.core().bufs.write_states(&state.arrays())
    }

    fn load(&mut self, grid: S::Grid, state: Option<S::State>) -> Result<()> {
        let mut fresh = self.fresh(grid)?;
        if let Some(state) = state {
            fresh.core().bufs.write_states(&state.arrays())?;
        }
        // The background, the views and the figures of the steps so far stay.
        self.core_mut()
            .queue
            .carry_into(&mut fresh.core_mut().queue)?;
        *self = fresh;
        Ok(())
    }
}
