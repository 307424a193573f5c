//! Training steps submitted and not yet read: up to [`MAX_IN_FLIGHT`] batches on the queue (the
//! host records the next step while the device runs the earlier ones), and, per step since the
//! last [`StepsInFlight::take`], its readback slot (the steps' order), its batch size and the host
//! time of its recording.

use super::{BatchTimes, InFlight, StepTimes, TrainRays};
use anyhow::Result;

/// Batches a backend keeps on the queue before waiting for the oldest.
pub const MAX_IN_FLIGHT: usize = 2;

/// What a backend keeps about a submitted step until its figures are read.
#[derive(Clone, Copy, Debug, Default)]
pub struct StepMeta {
    /// Rays in the batch.
    pub n: usize,
    /// Host time of the step up to its submission.
    pub host: StepTimes,
}

/// The steps submitted since the last `take`, in order: their slot is their index.
#[derive(Default)]
pub struct StepsInFlight {
    steps: Vec<(InFlight, StepMeta)>,
    /// Steps from the first whose fence has not been waited for.
    complete: usize,
    /// View set and batch size of the last sampled step.
    shape: Option<(u64, usize)>,
}

impl StepsInFlight {
    /// Steps submitted since the last `take` (the readback slot of the next one).
    pub fn pending(&self) -> usize {
        self.steps.len()
    }

    /// Before recording a step on `src`'s rays: wait for the steps in flight where the step's
    /// buffers may change under them — host rays are written into buffers an earlier step may
    /// still read, and another view set or batch size may reallocate the batch buffers.
    pub fn before_step(&mut self, src: &TrainRays) -> Result<()> {
        match src {
            TrainRays::Host { .. } => self.settle(),
            TrainRays::Sampled { id, n, .. } => {
                if self.shape != Some((*id, *n)) {
                    self.settle()?;
                    self.shape = Some((*id, *n));
                }
                Ok(())
            }
        }
    }

    /// Add a submitted step; waits for the oldest steps beyond [`MAX_IN_FLIGHT`].
    pub fn push(&mut self, f: InFlight, meta: StepMeta) -> Result<()> {
        self.steps.push((f, meta));
        while self.steps.len() - self.complete > MAX_IN_FLIGHT {
            self.steps[self.complete].0.wait_fence()?;
            self.complete += 1;
        }
        Ok(())
    }

    /// Wait for every submitted step: the device is then done with the backend's buffers, which
    /// the host may read, write or free.
    pub fn settle(&mut self) -> Result<()> {
        for (f, _) in &mut self.steps[self.complete..] {
            f.wait_fence()?;
        }
        self.complete = self.steps.len();
        Ok(())
    }

    /// Every step since the last `take`, completed, in order (slot i is step i), with its
    /// device times (read once all have completed); the slots are free again.
    pub fn take(&mut self) -> Result<Vec<(StepMeta, BatchTimes)>> {
        self.settle()?;
        self.complete = 0;
        std::mem::take(&mut self.steps)
            .into_iter()
            .map(|(f, meta)| Ok((meta, f.wait()?)))
            .collect()
    }
}
