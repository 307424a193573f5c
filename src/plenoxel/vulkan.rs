//! The Vulkan stage-1 backend: grid, gradients, optimiser state and the training views live in
//! device buffers; a training step is one batch (step reset → sample_rays when the batch is drawn
//! on the device → the kernels of the step's [`PlenoxelPlan`], in its order) and one submission.

use super::plan::{PlenoxelPass, PlenoxelPlan, TvField};
use super::{march_params, Gradients, Plenoxels, StepParams, StepStats};
use crate::abi::buffers::Background;
use crate::abi::buffers::PlenoxelParams;
use crate::abi::buffers::StepHeader;
use crate::abi::rays::SampledRays;
use crate::abi::regularisers::TvChunk;
use crate::abi::step::{step_record, STEP_FLAGS, STEP_RESET_BYTES};
use crate::abi::train::RmsProp;
use crate::data::TrainViews;
use crate::gpu::{
    record_background_step, record_loss_sum, record_optim_args, Batch, BatchTimes, Gpu, GpuBuffer,
    Phase, PhaseClock, RayBuffers, Readback, StepMeta, StepsInFlight, TrainRays, TrainViewBuffers,
    STEP_SLOTS,
};
use crate::grid::{Grid, SH_DIM};
use crate::kernels;
use crate::math::plenoxel::{occ_dims, PlenoxelCounts};
use anyhow::{ensure, Result};
use std::cell::RefCell;

/// Device-resident stage-1 state.
pub struct VulkanPlenoxels {
    /// Steps submitted and not yet read. First, so that dropping the backend waits for them
    /// before any buffer they use is freed. In a `RefCell` because reading state (`grid`, …)
    /// must wait for them too.
    steps: RefCell<StepsInFlight>,
    /// Figures of completed steps not yet taken.
    done: Vec<(StepStats, BatchTimes)>,
    gpu: Gpu,
    meta: Grid,
    links: GpuBuffer,
    density: GpuBuffer,
    sh: GpuBuffer,
    occ: GpuBuffer,
    grad_density: GpuBuffer,
    grad_sh: GpuBuffer,
    state_density: GpuBuffer,
    state_sh: GpuBuffer,
    /// Step record (glsl/lib/step.glsl): `StepHeader` (touched count, sample counters, n),
    /// flags, list.
    step: GpuBuffer,
    /// Indirect dispatch arguments of rmsprop_sparse.
    args: GpuBuffer,
    /// plenoxel_train's params buffer (written in each training batch's command stream).
    params: GpuBuffer,
    /// The background (`Background`): read by the render and training kernels, and, when
    /// learned, its gradient accumulated and stepped on the device (`background_step`) so that a
    /// step needs no host round trip for it.
    bg: GpuBuffer,
    /// Whether `bg` is learned (the host's copy of its flag: `background_step` is recorded then).
    bg_learned: bool,
    /// Per-batch rays, targets and per-ray output: rgb (3 floats) for render, the squared error
    /// (1 float) for training.
    rays: RayBuffers,
    /// Per training step since the figures were last read, a slot: the squared-error sum and
    /// the counters.
    readback: Readback,
    /// The training views and sampled batches (uploaded by the first sampled step; kept by
    /// `load`).
    views: Option<TrainViewBuffers>,
}

impl VulkanPlenoxels {
    pub fn new(gpu: &Gpu, grid: Grid) -> Result<Self> {
        let n = grid.allocated();
        let nb = occ_dims(grid.res);
        Ok(VulkanPlenoxels {
            steps: RefCell::default(),
            done: Vec::new(),
            gpu: gpu.clone(),
            links: gpu.upload(&grid.links)?,
            density: gpu.upload(&grid.density)?,
            sh: gpu.upload(&grid.sh)?,
            occ: gpu.zeros::<u32>((nb[0] * nb[1] * nb[2]) as usize)?,
            grad_density: gpu.zeros::<f32>(n)?,
            grad_sh: gpu.zeros::<f32>(n * SH_DIM)?,
            state_density: gpu.zeros::<f32>(n)?,
            state_sh: gpu.zeros::<f32>(n * SH_DIM)?,
            step: gpu.upload(&step_record(n, &[]))?,
            args: gpu.zeros::<u32>(3)?,
            params: gpu.host_to_device::<PlenoxelParams>(1)?,
            bg: gpu.upload(&[Background::new([1.0; 3], false)])?,
            bg_learned: false,
            rays: RayBuffers::new(3 * std::mem::size_of::<f32>()),
            readback: Readback::new(
                gpu,
                // The squared-error sum (one float), the counters.
                &[4, std::mem::size_of::<PlenoxelCounts>() as u64],
                STEP_SLOTS,
            )?,
            views: None,
            meta: Grid {
                links: Vec::new(),
                density: Vec::new(),
                sh: Vec::new(),
                ..grid
            },
        })
    }

    fn allocated(&self) -> usize {
        (self.density.size() / 4) as usize
    }

    fn record_occupancy(&self, b: &mut Batch) -> Result<()> {
        let nb = occ_dims(self.meta.res);
        b.dispatch_1d(
            &kernels::occupancy::INFO,
            &kernels::occupancy::Push {
                links: self.links.address(),
                density: self.density.address(),
                occ: self.occ.address(),
                res: self.meta.res,
                ..Default::default()
            },
            nb[0] * nb[1] * nb[2],
        )
    }

    fn read_stats(&self) -> Result<PlenoxelCounts> {
        Ok(self.step.download_range::<StepHeader>(0, 1)?[0].stats)
    }

    /// Record clearing the step's touched count and sample counters.
    fn record_step_reset(&self, b: &mut Batch) {
        b.fill_zero_range(&self.step, 0, STEP_RESET_BYTES);
    }

    /// Record the sparse RMSProp step over the vertices touched this step.
    fn record_rmsprop(&self, b: &mut Batch, p: &RmsProp) -> Result<()> {
        record_optim_args(b, &self.step, &self.args)?;
        b.dispatch_indirect(
            &kernels::rmsprop_sparse::INFO,
            &kernels::rmsprop_sparse::Push {
                density: self.density.address(),
                sh: self.sh.address(),
                grad_density: self.grad_density.address(),
                grad_sh: self.grad_sh.address(),
                state_density: self.state_density.address(),
                state_sh: self.state_sh.address(),
                step: self.step.address(),
                lr_sigma: p.lr_sigma,
                lr_sh: p.lr_sh,
                beta: p.beta,
                eps: p.eps,
            },
            &self.args,
        )
    }

    /// Upload rays (and targets), start a batch and record the step reset (the upload charged to
    /// `clock`). Returns the batch and the device addresses of the rays, targets and per-ray
    /// output.
    fn begin(
        &mut self,
        rays: &[f32],
        targets: Option<&[f32]>,
        clock: &mut PhaseClock,
    ) -> Result<(Batch, [u64; 3])> {
        let addrs = self.rays.upload(&self.gpu, rays, targets)?;
        clock.mark(Phase::Upload);
        let mut b = self.gpu.batch()?;
        self.record_step_reset(&mut b);
        Ok((b, addrs))
    }

    /// Start a batch with the step reset and the training rays (uploaded, or drawn by
    /// `sample_rays`). Returns it with the addresses of rays, targets and per-ray output.
    fn begin_train(&mut self, src: TrainRays, clock: &mut PhaseClock) -> Result<(Batch, [u64; 3])> {
        match src {
            TrainRays::Host { rays, targets } => {
                let n = src.len();
                ensure!(
                    n > 0 && targets.len() == 3 * n,
                    "batch of {n} rays with {} targets",
                    targets.len() / 3
                );
                self.begin(rays, Some(targets), clock)
            }
            TrainRays::Sampled { id, set, seed, n } => {
                TrainViewBuffers::ensure(&mut self.views, &self.gpu, id, set, n)?;
                let [_, _, out] = self.rays.reserve(&self.gpu, n)?;
                clock.mark(Phase::Upload);
                let mut b = self.gpu.batch()?;
                self.record_step_reset(&mut b);
                let views = self.views.as_ref().expect("ensured");
                let at = views.record_sample(&mut b, set, seed, n)?;
                clock.mark(Phase::Sampling);
                Ok((b, [at.rays, at.targets, out]))
            }
        }
    }

    /// Start the batch of `src`'s rays and record `plan`'s passes on it, in order.
    fn record_plan(
        &mut self,
        src: TrainRays,
        plan: &PlenoxelPlan,
        clock: &mut PhaseClock,
    ) -> Result<Batch> {
        let n = src.len();
        let (mut b, rays) = self.begin_train(src, clock)?;
        for pass in plan.passes() {
            match pass {
                PlenoxelPass::Occupancy => self.record_occupancy(&mut b)?,
                PlenoxelPass::Train {
                    stop_thresh,
                    grad_scale,
                } => self.record_train(&mut b, *stop_thresh, *grad_scale, rays, n)?,
                PlenoxelPass::Tv { field, chunk } => self.record_tv(&mut b, *field, chunk)?,
                PlenoxelPass::RmsProp(h) => self.record_rmsprop(&mut b, h)?,
                PlenoxelPass::Background { lr, beta, eps } => {
                    record_background_step(&mut b, &self.bg, *lr, *beta, *eps)?
                }
            }
        }
        Ok(b)
    }

    /// Write the params buffer for a training pass over `n` rays (in the command stream) and
    /// record the fused train kernel (gradients += data term).
    fn record_train(
        &self,
        b: &mut Batch,
        stop_thresh: f32,
        grad_scale: f32,
        [ray_buf, target_buf, loss_buf]: [u64; 3],
        n: usize,
    ) -> Result<()> {
        let mp = march_params(&self.meta, stop_thresh);
        b.update(
            &self.params,
            0,
            &[PlenoxelParams {
                scale: mp.scale,
                offset: mp.offset,
                stop_thresh,
                grad_scale,
            }],
        )?;
        b.dispatch_1d(
            &kernels::plenoxel_train::INFO,
            &kernels::plenoxel_train::Push {
                links: self.links.address(),
                density: self.density.address(),
                sh: self.sh.address(),
                occ: self.occ.address(),
                rays: ray_buf,
                targets: target_buf,
                grad_density: self.grad_density.address(),
                grad_sh: self.grad_sh.address(),
                ray_loss: loss_buf,
                step: self.step.address(),
                params: self.params.address(),
                bg: self.bg.address(),
                res: self.meta.res,
                n_rays: n as u32,
            },
            n as u32,
        )
    }

    /// Record TV on `field` over `c`'s slots (the dispatch covers the chunk and the slots whose
    /// forward neighbours lie in it).
    fn record_tv(&self, b: &mut Batch, field: TvField, c: &TvChunk) -> Result<()> {
        let (data, grad) = match field {
            TvField::Density => (&self.density, &self.grad_density),
            TvField::Sh => (&self.sh, &self.grad_sh),
        };
        b.dispatch_1d(
            &kernels::tv::INFO,
            &kernels::tv::Push {
                links: self.links.address(),
                data: data.address(),
                grad: grad.address(),
                step: self.step.address(),
                res: c.res,
                start: c.start,
                count: c.count,
                channels: c.channels,
                scale: c.scale,
                touch_bits: c.touch,
            },
            c.count + c.res[1] * c.res[2],
        )
    }

    /// Wait for the steps in flight (before the host reads, writes or frees what they use).
    fn settle(&self) -> Result<()> {
        self.steps.borrow_mut().settle()
    }

    /// Read the figures of every step submitted since the last read into `done`.
    fn collect(&mut self) -> Result<()> {
        let steps = self.steps.get_mut().take()?;
        for (slot, (meta, times)) in steps.into_iter().enumerate() {
            let mut clock = PhaseClock::start();
            let sum: Vec<f32> = self.readback.part(slot, 0)?;
            let counts = self.readback.part::<PlenoxelCounts>(slot, 1)?[0];
            clock.mark(Phase::Readback);
            let mut host = meta.host;
            host.add(&times.host);
            host.add(&clock.times);
            let stats = StepStats {
                mse: sum[0] as f64 / (3 * meta.n.max(1)) as f64,
                counts,
                device_ns: times.total_ns(),
                host,
            };
            self.done.push((stats, times));
        }
        Ok(())
    }

    /// Record the step's plan on one batch and submit it without waiting (up to
    /// `MAX_IN_FLIGHT` steps run on the device while the host records the next); its figures
    /// come back with [`Self::take_timed`].
    pub fn submit_step(&mut self, src: TrainRays, p: &StepParams) -> Result<()> {
        let n = src.len();
        let mut clock = PhaseClock::start();
        let plan = PlenoxelPlan::step(p, self.meta.res, n, self.bg_learned)?;
        self.steps.get_mut().before_step(&src)?;
        if self.steps.get_mut().pending() == self.readback.slots() {
            self.collect()?;
        }
        let slot = self.steps.get_mut().pending();
        let mut b = self.record_plan(src, &plan, &mut clock)?;
        // The step's figures into its slot: the squared error summed on the device, the
        // counters copied.
        let out = self.rays.out().address();
        record_loss_sum(&mut b, out, self.readback.address(slot, 0), n, 1, 1)?;
        let stats = std::mem::offset_of!(StepHeader, stats) as u64;
        self.readback.copy(&mut b, slot, 1, &self.step, stats);
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

    /// The figures of every step submitted since they were last taken, in order, with the
    /// device times of their dispatches (waits for the steps in flight).
    pub fn take_timed(&mut self) -> Result<Vec<(StepStats, BatchTimes)>> {
        self.collect()?;
        Ok(std::mem::take(&mut self.done))
    }

    /// One training step on `src`'s rays, waited for: its figures.
    /// The figures of earlier steps not yet taken stay for `take_stats`.
    fn train_step(&mut self, src: TrainRays, p: &StepParams) -> Result<StepStats> {
        self.submit_step(src, p)?;
        self.collect()?;
        let last = self.done.pop();
        Ok(last
            .ok_or_else(|| anyhow::anyhow!("a submitted step left no figures"))?
            .0)
    }

    /// The last sampled batch of `n` rays.
    pub fn sampled_batch(&self, n: usize) -> Result<SampledRays> {
        self.settle()?;
        let views = self.views.as_ref();
        let views = views.ok_or_else(|| anyhow::anyhow!("no batch was sampled"))?;
        views.download_batch(n)
    }

    /// Per-ray squared error of the last training pass over `n` rays.
    fn ray_loss(&self, n: usize) -> Result<Vec<f32>> {
        let mut loss: Vec<f32> = self.rays.out().download()?;
        loss.truncate(n);
        Ok(loss)
    }
}

impl Plenoxels for VulkanPlenoxels {
    fn name(&self) -> &'static str {
        "vulkan"
    }

    fn step(&mut self, rays: &[f32], targets: &[f32], p: &StepParams) -> Result<StepStats> {
        self.train_step(TrainRays::Host { rays, targets }, p)
    }

    fn step_sampled(
        &mut self,
        views: &TrainViews,
        seed: u64,
        n: usize,
        p: &StepParams,
    ) -> Result<()> {
        super::uniform_views(views)?;
        let src = TrainRays::Sampled {
            id: views.id(),
            set: views.set(),
            seed,
            n,
        };
        self.submit_step(src, p)
    }

    fn take_stats(&mut self) -> Result<Vec<StepStats>> {
        Ok(self.take_timed()?.into_iter().map(|(s, _)| s).collect())
    }

    fn gradients(&mut self, rays: &[f32], targets: &[f32], stop_thresh: f32) -> Result<Gradients> {
        self.settle()?;
        let n = rays.len() / 6;
        let plan = PlenoxelPlan::gradients(stop_thresh, n);
        let src = TrainRays::Host { rays, targets };
        self.record_plan(src, &plan, &mut PhaseClock::start())?
            .submit()?;
        let mut bg: Background = self.bg.download()?[0];
        let g = Gradients {
            ray_loss: self.ray_loss(n)?,
            density: self.grad_density.download()?,
            sh: self.grad_sh.download()?,
            background: bg.grad,
            counts: self.read_stats()?,
        };
        bg.grad = [0.0; 3];
        self.bg.write(&[bg])?;
        // Leave no gradient or touched flag behind for the next step.
        let mut b = self.gpu.batch()?;
        b.fill_zero(&self.grad_density);
        b.fill_zero(&self.grad_sh);
        b.fill_zero_range(
            &self.step,
            4 * STEP_FLAGS as u64,
            4 * self.allocated() as u64,
        );
        b.submit()?;
        Ok(g)
    }

    fn render(&mut self, rays: &[f32], stop_thresh: f32) -> Result<(Vec<f32>, PlenoxelCounts)> {
        self.settle()?;
        let n = rays.len() / 6;
        let mp = march_params(&self.meta, stop_thresh);
        let (mut b, [ray_buf, _, out_buf]) = self.begin(rays, None, &mut PhaseClock::start())?;
        self.record_occupancy(&mut b)?;
        b.dispatch_1d(
            &kernels::plenoxel_fwd::INFO,
            &kernels::plenoxel_fwd::Push {
                links: self.links.address(),
                density: self.density.address(),
                sh: self.sh.address(),
                occ: self.occ.address(),
                rays: ray_buf,
                rgb: out_buf,
                step: self.step.address(),
                bg: self.bg.address(),
                res: self.meta.res,
                scale: mp.scale,
                offset: mp.offset,
                n_rays: n as u32,
                stop_thresh,
                ..Default::default()
            },
            n as u32,
        )?;
        b.submit()?;
        let mut rgb: Vec<f32> = self.rays.out().download()?;
        rgb.truncate(3 * n);
        Ok((rgb, self.read_stats()?))
    }

    fn max_weights(&mut self, rays: &[f32], stop_thresh: f32) -> Result<Vec<f32>> {
        self.settle()?;
        let n = rays.len() / 6;
        let mp = march_params(&self.meta, stop_thresh);
        let out = self.gpu.zeros::<u32>(self.allocated())?;
        let (mut b, [ray_buf, _, _]) = self.begin(rays, None, &mut PhaseClock::start())?;
        self.record_occupancy(&mut b)?;
        b.dispatch_1d(
            &kernels::plenoxel_weights::INFO,
            &kernels::plenoxel_weights::Push {
                links: self.links.address(),
                density: self.density.address(),
                sh: self.sh.address(),
                occ: self.occ.address(),
                rays: ray_buf,
                max_weight: out.address(),
                res: self.meta.res,
                scale: mp.scale,
                offset: mp.offset,
                n_rays: n as u32,
                stop_thresh,
                ..Default::default()
            },
            n as u32,
        )?;
        b.submit()?;
        Ok(out
            .download::<u32>()?
            .into_iter()
            .map(f32::from_bits)
            .collect())
    }

    fn grid(&self) -> Result<Grid> {
        self.settle()?;
        Ok(Grid {
            links: self.links.download()?,
            density: self.density.download()?,
            sh: self.sh.download()?,
            ..self.meta.clone()
        })
    }

    fn shape(&self) -> ([u32; 3], usize) {
        (self.meta.res, self.allocated())
    }

    fn optimizer_state(&self) -> Result<(Vec<f32>, Vec<f32>)> {
        self.settle()?;
        Ok((self.state_density.download()?, self.state_sh.download()?))
    }

    fn load(&mut self, grid: Grid, state: Option<(Vec<f32>, Vec<f32>)>) -> Result<()> {
        let n = grid.allocated();
        if let Some((sd, ss)) = &state {
            ensure!(
                sd.len() == n && ss.len() == n * SH_DIM,
                "optimizer state does not match the grid"
            );
        }
        // The figures of the steps so far stay (read now: the buffers they sit in go).
        self.collect()?;
        let bg = self.background()?;
        let mut fresh = VulkanPlenoxels::new(&self.gpu, grid)?;
        if let Some((sd, ss)) = state {
            fresh.state_density.write(&sd)?;
            fresh.state_sh.write(&ss)?;
        }
        fresh.set_background(bg)?;
        fresh.views = self.views.take();
        fresh.done = std::mem::take(&mut self.done);
        *self = fresh;
        Ok(())
    }

    fn background(&self) -> Result<Background> {
        self.settle()?;
        Ok(self.bg.download()?[0])
    }

    fn set_background(&mut self, bg: Background) -> Result<()> {
        self.settle()?;
        self.bg.write(&[bg])?;
        self.bg_learned = bg.learned();
        Ok(())
    }
}
