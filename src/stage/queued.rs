//! What both stages' Vulkan backends do alike, written once: a Vulkan backend names its
//! [`StepQueue`], how it records a training step, and how it downloads and rebuilds its grid
//! ([`QueuedBackend`]); its [`StageBackend`] follows (submission, the reads that wait for the
//! steps in flight, the rebuild that keeps the background, views and figures).

use super::{Stage, StageBackend, StepStore};
use crate::gpu::{Batch, PhaseClock, SlotFigures, StepQueue, TrainRays};
use anyhow::Result;

/// A Vulkan backend of stage `S`: its steps go through a [`StepQueue`].
pub trait QueuedBackend<S: Stage>: Sized {
    fn queue(&self) -> &StepQueue<S::Stats>;
    fn queue_mut(&mut self) -> &mut StepQueue<S::Stats>;
    /// Start the batch of a training step on `src`'s rays and record the step's plan on it,
    /// with the step's figures into the readback `slot` (host time charged to `clock`).
    fn record_step(
        &mut self,
        src: TrainRays,
        p: &S::Params,
        slot: usize,
        clock: &mut PhaseClock,
    ) -> Result<Batch>;
    /// The grid, downloaded (no step is in flight).
    fn download_grid(&self) -> Result<S::Grid>;
    /// The optimiser's running averages, downloaded (no step is in flight).
    fn download_state(&self) -> Result<S::State>;
    /// Bytes of a copy of the grid and the running averages.
    fn copy_bytes(&self) -> u64;
    /// A backend on the same device for `grid`, with the optimiser state `state` (zero when
    /// `None`) and a fresh queue.
    fn rebuild(&self, grid: S::Grid, state: Option<S::State>) -> Result<Self>;
}

impl<S: Stage, B: QueuedBackend<S>> StageBackend<S> for B
where
    S::Stats: SlotFigures,
{
    fn store(&self) -> &dyn StepStore<S::Stats> {
        self.queue()
    }

    fn store_mut(&mut self) -> &mut dyn StepStore<S::Stats> {
        self.queue_mut()
    }

    /// Record the step on one batch and submit it without waiting (up to `MAX_IN_FLIGHT` steps
    /// run on the device while the host records the next).
    fn submit(&mut self, src: TrainRays, p: &S::Params) -> Result<()> {
        let n = src.len();
        let mut clock = PhaseClock::start();
        let slot = self.queue_mut().slot_for(&src)?;
        let b = self.record_step(src, p, slot, &mut clock)?;
        self.queue_mut().submit(b, n, clock)
    }

    fn grid(&self) -> Result<S::Grid> {
        self.queue().settle()?;
        self.download_grid()
    }

    fn optimizer_state(&self) -> Result<S::State> {
        self.queue().settle()?;
        self.download_state()
    }

    fn state_bytes(&self) -> u64 {
        self.copy_bytes()
    }

    fn load(&mut self, grid: S::Grid, state: Option<S::State>) -> Result<()> {
        let mut fresh = self.rebuild(grid, state)?;
        // The background, the views and the figures of the steps so far stay.
        self.queue_mut().carry_into(fresh.queue_mut())?;
        *self = fresh;
        Ok(())
    }
}
