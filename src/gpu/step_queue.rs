//! What both stages' Vulkan backends keep for their training steps: the steps in flight and their
//! figures (each step's sums and counters copied into a readback slot, read in groups), the
//! per-batch ray buffers, the training views on the device, and the background the kernels
//! composite on (a learned one is stepped on the device, so a step needs no host round trip).

use super::{
    Batch, BatchTimes, Gpu, GpuBuffer, Phase, PhaseClock, RayBuffers, Readback, SampledAt,
    StepMeta, StepTimes, StepsInFlight, TrainRays, TrainViewBuffers, STEP_SLOTS,
};
use crate::abi::buffers::Background;
use crate::abi::rays::{SampleSet, SampledRays};
use anyhow::{anyhow, Result};
use std::cell::RefCell;

/// A step's figures as its readback slot holds them.
pub trait SlotFigures: Sized {
    /// The figures of a step of `n` rays in `slot` of `readback` (times not yet set).
    fn read(readback: &Readback, slot: usize, n: usize) -> Result<Self>;
    /// Set the step's device time (ns) and host time by phase.
    fn set_times(&mut self, device_ns: f64, host: StepTimes);
}

/// The training steps of a Vulkan backend, with figures of type `F`.
pub struct StepQueue<F> {
    /// Steps submitted and not yet read. First, so that dropping the queue waits for them before
    /// any buffer they use is freed (a backend holds its queue as its first field for the same
    /// reason). In a `RefCell` because reading state (`grid`, …) must wait for them too.
    steps: RefCell<StepsInFlight>,
    /// Figures of completed steps not yet taken.
    done: Vec<(F, BatchTimes)>,
    /// The background (`Background`): read by the render and training kernels, and, when
    /// learned, its gradient accumulated and stepped on the device (`background_step`).
    pub bg: GpuBuffer,
    /// Whether `bg` is learned (the host's copy of its flag: `background_step` is recorded then).
    pub bg_learned: bool,
    /// Per-batch rays, targets and per-ray output.
    pub rays: RayBuffers,
    /// Per training step since the figures were last read, a slot.
    pub readback: Readback,
    /// The training views and sampled batches (uploaded by the first sampled step; carried over
    /// by [`Self::carry_into`]).
    views: Option<TrainViewBuffers>,
}

impl<F: SlotFigures> StepQueue<F> {
    /// A queue whose batches output `out_bytes` per ray and whose slots hold `parts` (bytes
    /// each), on a white fixed background.
    pub fn new(gpu: &Gpu, out_bytes: usize, parts: &[u64]) -> Result<Self> {
        Ok(StepQueue {
            steps: RefCell::default(),
            done: Vec::new(),
            bg: gpu.upload(&[Background::new([1.0; 3], false)])?,
            bg_learned: false,
            rays: RayBuffers::new(out_bytes),
            readback: Readback::new(gpu, parts, STEP_SLOTS)?,
            views: None,
        })
    }

    /// Wait for the steps in flight (before the host reads, writes or frees what they use).
    pub fn settle(&self) -> Result<()> {
        self.steps.borrow_mut().settle()
    }

    /// Read the figures of every step submitted since the last read.
    fn collect(&mut self) -> Result<()> {
        let steps = self.steps.get_mut().take()?;
        for (slot, (meta, times)) in steps.into_iter().enumerate() {
            let mut clock = PhaseClock::start();
            let mut figures = F::read(&self.readback, slot, meta.n)?;
            clock.mark(Phase::Readback);
            let mut host = meta.host;
            host.add(&times.host);
            host.add(&clock.times);
            figures.set_times(times.total_ns(), host);
            self.done.push((figures, times));
        }
        Ok(())
    }

    /// The figures of every step submitted since they were last taken, in order, with the
    /// device times of their dispatches (waits for the steps in flight).
    pub fn take_timed(&mut self) -> Result<Vec<(F, BatchTimes)>> {
        self.collect()?;
        Ok(std::mem::take(&mut self.done))
    }

    /// The figures of every step submitted since they were last taken, in order.
    pub fn take_figures(&mut self) -> Result<Vec<F>> {
        Ok(self.take_timed()?.into_iter().map(|(f, _)| f).collect())
    }

    /// The figures of the step submitted last, waited for; those of earlier steps not yet taken
    /// stay.
    pub fn last(&mut self) -> Result<(F, BatchTimes)> {
        self.collect()?;
        let last = self.done.pop();
        last.ok_or_else(|| anyhow!("a submitted step left no figures"))
    }

    /// Before a step on `src` is recorded: the slot its figures go to (the figures are read
    /// first when every slot is taken).
    pub fn slot_for(&mut self, src: &TrainRays) -> Result<usize> {
        self.steps.get_mut().before_step(src)?;
        if self.steps.get_mut().pending() == self.readback.slots() {
            self.collect()?;
        }
        Ok(self.steps.get_mut().pending())
    }

    /// Submit a recorded step of `n` rays without waiting (up to `MAX_IN_FLIGHT` steps run on
    /// the device while the host records the next); `clock` has its host time so far.
    pub fn submit(&mut self, b: Batch, n: usize, mut clock: PhaseClock) -> Result<()> {
        clock.mark(Phase::Record);
        let f = b.submit_async()?;
        self.steps.get_mut().push(
            f,
            StepMeta {
                n,
                host: clock.times,
            },
        )
    }

    /// Before a batch of `n` rays drawn on the device from `set` (id `id`) is recorded: the set
    /// uploaded unless it is there, room made for the batch; returns the address of the per-ray
    /// output. The upload is charged to `clock`.
    pub fn reserve_sampled(
        &mut self,
        gpu: &Gpu,
        id: u64,
        set: &SampleSet,
        n: usize,
        clock: &mut PhaseClock,
    ) -> Result<u64> {
        TrainViewBuffers::ensure(&mut self.views, gpu, id, set, n)?;
        let [_, _, out] = self.rays.reserve(gpu, n)?;
        clock.mark(Phase::Upload);
        Ok(out)
    }

    /// Record drawing the batch [`Self::reserve_sampled`] made room for (charged to `clock`);
    /// the addresses of its rays, targets and weights.
    pub fn record_sample(
        &self,
        b: &mut Batch,
        set: &SampleSet,
        seed: u64,
        n: usize,
        clock: &mut PhaseClock,
    ) -> Result<SampledAt> {
        let views = self.views.as_ref();
        let views = views.ok_or_else(|| anyhow!("no room was made for a sampled batch"))?;
        let at = views.record_sample(b, set, seed, n)?;
        clock.mark(Phase::Sampling);
        Ok(at)
    }

    /// The last sampled batch of `n` rays.
    pub fn sampled_batch(&self, n: usize) -> Result<SampledRays> {
        self.settle()?;
        let views = self.views.as_ref();
        let views = views.ok_or_else(|| anyhow!("no batch was sampled"))?;
        views.download_batch(n)
    }

    /// The background with its optimiser state.
    pub fn background(&self) -> Result<Background> {
        self.settle()?;
        Ok(self.bg.download()?[0])
    }

    /// Replace the background (colour, whether it is learned, its optimiser state).
    pub fn set_background(&mut self, bg: Background) -> Result<()> {
        self.settle()?;
        self.bg.write(&[bg])?;
        self.bg_learned = bg.learned();
        Ok(())
    }

    /// Hand the background, the training views and the figures not yet taken to `fresh`, the
    /// queue of a backend rebuilt for a new grid (the figures are read now: the buffers they sit
    /// in go with this queue).
    pub fn carry_into(&mut self, fresh: &mut Self) -> Result<()> {
        self.collect()?;
        fresh.set_background(self.background()?)?;
        fresh.views = self.views.take();
        fresh.done = std::mem::take(&mut self.done);
        Ok(())
    }
}
