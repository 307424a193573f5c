//! What both stages' Vulkan backends keep for their training steps: the device, the steps in
//! flight and their figures (each step's sums and counters copied into a readback slot, read in
//! groups), the step record with the optimiser's indirect arguments, the per-batch ray buffers,
//! the training views on the device, and the background the kernels composite on (a learned one
//! is stepped on the device, so a step needs no host round trip).

use super::{
    address_words, record_loss_sum, record_optim_args, Batch, Gpu, GpuBuffer, Phase, PhaseClock,
    RayBuffers, Readback, SphereBuffers, StepMeta, StepTiming, StepsInFlight, TrainRays,
    TrainViewBuffers, STEP_SLOTS,
};
use crate::abi::buffers::{Background, StepHeader};
use crate::abi::rays::SampledRays;
use crate::abi::step::{STEP_FLAGS, STEP_RESET_BYTES};
use crate::math::background_msi::SphereTable;
use anyhow::{anyhow, ensure, Result};
use bytemuck::Pod;
use std::cell::RefCell;

/// A step's figures as its readback slot holds them.
pub trait SlotFigures: Sized {
    /// The figures of a step of `n` rays in `slot` of `readback` (their timing apart).
    fn read(readback: &Readback, slot: usize, n: usize) -> Result<Self>;
}

/// Device addresses of a training batch: rays (6 floats each), targets (3 floats each),
/// per-ray importance weights (0: every weight 1) and the per-ray output.
#[derive(Clone, Copy, Debug)]
pub struct BatchRays {
    pub rays: u64,
    pub targets: u64,
    pub weights: u64,
    pub out: u64,
}

/// The training steps of a Vulkan backend, with figures of type `F`.
pub struct StepQueue<F> {
    /// Steps submitted and not yet read. First, so that dropping the queue waits for them before
    /// any buffer they use is freed (a backend holds its queue as its first field for the same
    /// reason). In a `RefCell` because reading state (`grid`, …) must wait for them too.
    steps: RefCell<StepsInFlight>,
    /// Figures of completed steps not yet taken, with the steps' timing.
    done: Vec<(F, StepTiming)>,
    gpu: Gpu,
    /// The step record (glsl/lib/step.glsl): `StepHeader` (touched count, sample counters, n),
    /// the touched flags and list.
    pub step: GpuBuffer,
    /// Indirect dispatch arguments of the optimiser's pass over the touched vertices
    /// (`optim_args`).
    pub args: GpuBuffer,
    /// The background (`Background`): read by the render and training kernels, and, when
    /// learned, its gradient accumulated and stepped on the device (`background_step`).
    pub bg: GpuBuffer,
    /// Whether `bg` is learned (the host's copy of its flag: `background_step` is recorded then).
    pub bg_learned: bool,
    /// The background's spheres (`bg` holds their address).
    pub spheres: Option<SphereBuffers>,
    /// Per-batch rays, targets and per-ray output.
    pub rays: RayBuffers,
    /// Per training step since the figures were last read, a slot.
    pub readback: Readback,
    /// The training views and sampled batches (uploaded by the first sampled step; carried over
    /// by [`Self::carry_into`]).
    views: Option<TrainViewBuffers>,
}

impl<F: SlotFigures> StepQueue<F> {
    /// A queue on `gpu` with the step record `step` (u32 words), whose batches output
    /// `out_bytes` per ray and whose slots hold `parts` (bytes each), on a white fixed background.
    pub fn new(gpu: &Gpu, step: &[u32], out_bytes: usize, parts: &[u64]) -> Result<Self> {
        Ok(StepQueue {
            steps: RefCell::default(),
            done: Vec::new(),
            gpu: gpu.clone(),
            step: gpu.upload(step)?,
            args: gpu.zeros::<u32>(3)?,
            bg: gpu.upload(&[Background::new([1.0; 3], false)])?,
            bg_learned: false,
            spheres: None,
            rays: RayBuffers::new(out_bytes),
            readback: Readback::new(gpu, parts, STEP_SLOTS)?,
            views: None,
        })
    }

    /// Wait for the steps in flight (before the host reads, writes or frees what they use).
    pub fn settle(&self) -> Result<()> {
        self.steps.borrow_mut().settle()
    }

    /// The device.
    pub fn gpu(&self) -> &Gpu {
        &self.gpu
    }

    /// The step record's header (as the last batch run left it).
    pub fn header(&self) -> Result<StepHeader> {
        Ok(self.step.download_range::<StepHeader>(0, 1)?[0])
    }

    /// Record `optim_args` on the step record: the indirect arguments in `args`.
    pub fn record_optim_args(&self, b: &mut Batch) -> Result<()> {
        record_optim_args(b, &self.step, &self.args)
    }

    /// Clear the gradient buffers `grads` and the touched flags of `rows` vertex rows (one
    /// submission, waited for), so that no gradient or flag stays behind for the next step.
    pub fn clear_gradients(&self, grads: &[&GpuBuffer], rows: usize) -> Result<()> {
        let mut b = self.gpu.batch()?;
        for g in grads {
            b.fill_zero(g);
        }
        if rows > 0 {
            b.fill_zero_range(&self.step, 4 * STEP_FLAGS as u64, 4 * rows as u64);
        }
        b.submit()?;
        Ok(())
    }

    /// Read the figures of every step submitted since the last read.
    fn collect(&mut self) -> Result<()> {
        let steps = self.steps.get_mut().take()?;
        for (slot, (meta, times)) in steps.into_iter().enumerate() {
            let mut clock = PhaseClock::start();
            let figures = F::read(&self.readback, slot, meta.n)?;
            clock.mark(Phase::Readback);
            let mut host = meta.host;
            host.add(&times.host);
            host.add(&clock.times);
            let timing = StepTiming {
                device_ns: times.total_ns(),
                host,
            };
            self.done.push((figures, timing));
        }
        Ok(())
    }

    /// The figures of every step submitted since they were last taken, in order, with their
    /// timing (waits for the steps in flight).
    pub fn take(&mut self) -> Result<Vec<(F, StepTiming)>> {
        self.collect()?;
        Ok(std::mem::take(&mut self.done))
    }

    /// The figures of the step submitted last with its timing, waited for; those of earlier
    /// steps not yet taken stay.
    pub fn last(&mut self) -> Result<(F, StepTiming)> {
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

    /// Record summing the batch's per-ray losses (`n` rays, `fields` floats from each ray's
    /// output of `stride` floats) into part 0 of `slot`.
    pub fn record_loss_sum(
        &self,
        b: &mut Batch,
        slot: usize,
        n: usize,
        stride: u32,
        fields: u32,
    ) -> Result<()> {
        let out = self.rays.out().address();
        record_loss_sum(b, out, self.readback.address(slot, 0), n, stride, fields)
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

    /// Start the batch of a training step on `src`'s rays: uploaded (host rays: 6 floats and a
    /// 3-float target each, at least one), or drawn on the device by `sample_rays` from the views
    /// (uploaded once); the batch opens with the step
    /// reset (the step record's touched count and counters) and clearing `counters`. The uploads
    /// are charged to `clock`'s upload, the draw's recording to its sampling. Returns the batch
    /// with the addresses of its rays.
    pub fn begin(
        &mut self,
        src: TrainRays,
        clock: &mut PhaseClock,
        counters: &[&GpuBuffer],
    ) -> Result<(Batch, BatchRays)> {
        let (id, set, seed, n) = match src {
            TrainRays::Host { rays, targets } => {
                let n = rays.len() / 6;
                ensure!(
                    n > 0 && rays.len() == 6 * n && targets.len() == 3 * n,
                    "batch of {} ray floats with {} target floats",
                    rays.len(),
                    targets.len()
                );
                return self.begin_host(rays, Some(targets), clock, counters);
            }
            TrainRays::Sampled { id, set, seed, n } => (id, set, seed, n),
        };
        let views = TrainViewBuffers::ensure(&mut self.views, &self.gpu, id, set, n)?;
        let [_, _, out] = self.rays.reserve(&self.gpu, n)?;
        clock.mark(Phase::Upload);
        let mut b = start_batch(&self.gpu, &self.step, counters)?;
        let at = views.record_sample(&mut b, set, seed, n)?;
        clock.mark(Phase::Sampling);
        let at = BatchRays {
            rays: at.rays,
            targets: at.targets,
            weights: at.weights,
            out,
        };
        Ok((b, at))
    }

    /// Upload `rays` (and `targets`) and start a batch as [`Self::begin`] does (the upload
    /// charged to `clock`). Returns the batch with the addresses of the rays (no weights).
    pub fn begin_host(
        &mut self,
        rays: &[f32],
        targets: Option<&[f32]>,
        clock: &mut PhaseClock,
        counters: &[&GpuBuffer],
    ) -> Result<(Batch, BatchRays)> {
        let [rays, targets, out] = self.rays.upload(&self.gpu, rays, targets)?;
        clock.mark(Phase::Upload);
        let b = start_batch(&self.gpu, &self.step, counters)?;
        let at = BatchRays {
            rays,
            targets,
            weights: 0,
            out,
        };
        Ok((b, at))
    }

    /// The first `n` elements of the last batch's per-ray output.
    pub fn ray_output<T: Pod>(&self, n: usize) -> Result<Vec<T>> {
        self.rays.out().download_range(0, n)
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

    /// The gradient of the background (a learned one's, else zero), read and cleared.
    pub fn take_background_grad(&self) -> Result<[f32; 3]> {
        let mut bg = self.background()?;
        let grad = bg.grad;
        bg.grad = [0.0; 3];
        self.bg.write(&[bg])?;
        Ok(grad)
    }

    /// The gradient of the spheres (learned ones', else empty), read and cleared.
    pub fn take_sphere_grad(&self) -> Result<Vec<f32>> {
        self.settle()?;
        match self.spheres.as_ref().filter(|s| s.shape.learn != 0) {
            Some(s) => s.take_grad(),
            None => Ok(Vec::new()),
        }
    }

    /// Replace the background (colour, whether it is learned, its optimiser state), in front
    /// of the spheres the queue holds.
    pub fn set_background(&mut self, bg: Background) -> Result<()> {
        self.settle()?;
        let spheres = self.spheres.as_ref().map_or(0, |s| s.shape_buf.address());
        self.bg.write(&[Background {
            spheres: address_words(spheres),
            ..bg
        }])?;
        self.bg_learned = bg.learned();
        Ok(())
    }

    /// The background's spheres with their optimiser state.
    pub fn spheres(&self) -> Result<Option<SphereTable>> {
        self.settle()?;
        self.spheres
            .as_ref()
            .map(SphereBuffers::download)
            .transpose()
    }

    /// Replace the background's spheres.
    pub fn set_spheres(&mut self, spheres: Option<SphereTable>) -> Result<()> {
        let bg = self.background()?;
        self.spheres = spheres
            .map(|t| SphereBuffers::upload(&self.gpu, &t))
            .transpose()?;
        self.set_background(bg)
    }

    /// Hand the background, the training views and the figures not yet taken to `fresh`, the
    /// queue of a backend rebuilt for a new grid (the figures are read now: the buffers they sit
    /// in go with this queue).
    pub fn carry_into(&mut self, fresh: &mut Self) -> Result<()> {
        self.collect()?;
        fresh.spheres = self.spheres.take();
        fresh.set_background(self.background()?)?;
        fresh.views = self.views.take();
        fresh.done = std::mem::take(&mut self.done);
        Ok(())
    }
}

/// A batch opening with the step reset of the step record `step` and clearing `counters`.
fn start_batch(gpu: &Gpu, step: &GpuBuffer, counters: &[&GpuBuffer]) -> Result<Batch> {
    let mut b = gpu.batch()?;
    b.fill_zero_range(step, 0, STEP_RESET_BYTES);
    for c in counters {
        b.fill_zero(c);
    }
    Ok(b)
}
