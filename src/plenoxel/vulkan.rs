//! The Vulkan stage-1 backend: grid, gradients, optimiser state and the training views live in
//! device buffers; a training step is one batch (step reset → sample_rays when the batch is drawn
//! on the device → the kernels of the step's [`PlenoxelPlan`], in its order) and one submission.

use super::plan::{PlenoxelPass, PlenoxelPlan, TvField};
use super::{
    march_params, state_bytes_of, Gradients, PlenoxelsBackend, PlenoxelsStage, PlenoxelsStepParams,
    PlenoxelsStepStats,
};
use crate::abi::buffers::PlenoxelParams;
use crate::abi::buffers::StepHeader;
use crate::abi::rays::SampledRays;
use crate::abi::step::step_record;
use crate::abi::train::RmsProp;
use crate::gpu::{
    record_background_step, record_tv, Batch, BatchRays, Gpu, GpuBuffer, PhaseClock, Readback,
    SlotFigures, StepQueue, StepTimes, TrainRays,
};
use crate::grid::{Grid, SH_DIM};
use crate::kernels;
use crate::math::plenoxel::{occ_dims, PlenoxelCounts};
use crate::stage::QueuedBackend;
use anyhow::{ensure, Result};

/// Device-resident stage-1 state.
pub struct VulkanPlenoxels {
    /// The steps in flight, their figures, the ray buffers, the training views and the
    /// background: per ray 3 floats of output (rgb) for a render, the squared error (1 float)
    /// for training; per step a slot with the squared-error sum and the counters. First, so
    /// that dropping the backend waits for the steps before any buffer they use is freed.
    queue: StepQueue<PlenoxelsStepStats>,
    meta: Grid,
    links: GpuBuffer,
    density: GpuBuffer,
    sh: GpuBuffer,
    occ: GpuBuffer,
    grad_density: GpuBuffer,
    grad_sh: GpuBuffer,
    state_density: GpuBuffer,
    state_sh: GpuBuffer,
    /// plenoxel_train's params buffer (written in each training batch's command stream).
    params: GpuBuffer,
}

impl VulkanPlenoxels {
    pub fn new(gpu: &Gpu, grid: Grid) -> Result<Self> {
        let n = grid.allocated();
        let nb = occ_dims(grid.res);
        Ok(VulkanPlenoxels {
            queue: StepQueue::new(
                gpu,
                &step_record(n, &[]),
                3 * std::mem::size_of::<f32>(),
                // The squared-error sum (one float), the counters.
                &[4, std::mem::size_of::<PlenoxelCounts>() as u64],
            )?,
            links: gpu.upload(&grid.links)?,
            density: gpu.upload(&grid.density)?,
            sh: gpu.upload(&grid.sh)?,
            occ: gpu.zeros::<u32>((nb[0] * nb[1] * nb[2]) as usize)?,
            grad_density: gpu.zeros::<f32>(n)?,
            grad_sh: gpu.zeros::<f32>(n * SH_DIM)?,
            state_density: gpu.zeros::<f32>(n)?,
            state_sh: gpu.zeros::<f32>(n * SH_DIM)?,
            params: gpu.host_to_device::<PlenoxelParams>(1)?,
            meta: grid.without_arrays(),
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
        Ok(self.queue.header()?.stats)
    }

    /// Record the sparse RMSProp step over the vertices touched this step.
    fn record_rmsprop(&self, b: &mut Batch, p: &RmsProp) -> Result<()> {
        self.queue.record_optim_args(b)?;
        b.dispatch_indirect(
            &kernels::rmsprop_sparse::INFO,
            &kernels::rmsprop_sparse::Push {
                density: self.density.address(),
                sh: self.sh.address(),
                grad_density: self.grad_density.address(),
                grad_sh: self.grad_sh.address(),
                state_density: self.state_density.address(),
                state_sh: self.state_sh.address(),
                step: self.queue.step.address(),
                lr_sigma: p.lr_sigma,
                lr_sh: p.lr_sh,
                beta: p.beta,
                eps: p.eps,
            },
            &self.queue.args,
        )
    }

    /// Start a batch with the step reset (clearing the touched count and sample counters) and
    /// the training rays (uploaded, or drawn by `sample_rays`).
    fn begin_train(
        &mut self,
        src: TrainRays,
        clock: &mut PhaseClock,
    ) -> Result<(Batch, BatchRays)> {
        if let TrainRays::Host { targets, .. } = src {
            let n = src.len();
            ensure!(
                n > 0 && targets.len() == 3 * n,
                "batch of {n} rays with {} targets",
                targets.len() / 3
            );
        }
        self.queue.begin(src, clock, &[])
    }

    /// Upload `rays` and start a batch with the step reset, for a render or a pass that reads
    /// no targets.
    fn begin_render(&mut self, rays: &[f32]) -> Result<(Batch, BatchRays)> {
        self.queue
            .begin_host(rays, None, &mut PhaseClock::start(), &[])
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
                PlenoxelPass::Tv { field, chunk } => {
                    let (data, grad) = match field {
                        TvField::Density => (&self.density, &self.grad_density),
                        TvField::Sh => (&self.sh, &self.grad_sh),
                    };
                    record_tv(&mut b, &self.links, data, grad, &self.queue.step, chunk)?
                }
                PlenoxelPass::RmsProp(h) => self.record_rmsprop(&mut b, h)?,
                PlenoxelPass::Background(s) => {
                    record_background_step(&mut b, &self.queue.bg, s.lr, s.beta, s.eps)?
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
        rays: BatchRays,
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
                rays: rays.rays,
                targets: rays.targets,
                grad_density: self.grad_density.address(),
                grad_sh: self.grad_sh.address(),
                ray_loss: rays.out,
                step: self.queue.step.address(),
                params: self.params.address(),
                bg: self.queue.bg.address(),
                res: self.meta.res,
                n_rays: n as u32,
            },
            n as u32,
        )
    }

    /// The last sampled batch of `n` rays.
    pub fn sampled_batch(&self, n: usize) -> Result<SampledRays> {
        self.queue.sampled_batch(n)
    }
}

impl QueuedBackend<PlenoxelsStage> for VulkanPlenoxels {
    fn queue(&self) -> &StepQueue<PlenoxelsStepStats> {
        &self.queue
    }

    fn queue_mut(&mut self) -> &mut StepQueue<PlenoxelsStepStats> {
        &mut self.queue
    }

    /// The step's plan, then its figures into `slot`: the squared error summed on the device,
    /// the counters copied.
    fn record_step(
        &mut self,
        src: TrainRays,
        p: &PlenoxelsStepParams,
        slot: usize,
        clock: &mut PhaseClock,
    ) -> Result<Batch> {
        let n = src.len();
        let plan = PlenoxelPlan::step(p, self.meta.res, n, self.queue.bg_learned)?;
        let mut b = self.record_plan(src, &plan, clock)?;
        self.queue.record_loss_sum(&mut b, slot, n, 1, 1)?;
        let stats = std::mem::offset_of!(StepHeader, stats) as u64;
        self.queue
            .readback
            .copy(&mut b, slot, 1, &self.queue.step, stats);
        Ok(b)
    }

    fn download_grid(&self) -> Result<Grid> {
        Ok(Grid {
            links: self.links.download()?,
            density: self.density.download()?,
            sh: self.sh.download()?,
            ..self.meta.clone()
        })
    }

    fn download_state(&self) -> Result<[Vec<f32>; 2]> {
        Ok([self.state_density.download()?, self.state_sh.download()?])
    }

    fn copy_bytes(&self) -> u64 {
        state_bytes_of(self.shape())
    }

    fn rebuild(&self, grid: Grid, state: Option<[Vec<f32>; 2]>) -> Result<Self> {
        let n = grid.allocated();
        if let Some([sd, ss]) = &state {
            ensure!(
                sd.len() == n && ss.len() == n * SH_DIM,
                "optimizer state does not match the grid"
            );
        }
        let fresh = VulkanPlenoxels::new(self.queue.gpu(), grid)?;
        if let Some([sd, ss]) = state {
            fresh.state_density.write(&sd)?;
            fresh.state_sh.write(&ss)?;
        }
        Ok(fresh)
    }
}

impl PlenoxelsBackend for VulkanPlenoxels {
    fn gradients(&mut self, rays: &[f32], targets: &[f32], stop_thresh: f32) -> Result<Gradients> {
        self.queue.settle()?;
        let n = rays.len() / 6;
        let plan = PlenoxelPlan::gradients(stop_thresh, n);
        let src = TrainRays::Host { rays, targets };
        self.record_plan(src, &plan, &mut PhaseClock::start())?
            .submit()?;
        let g = Gradients {
            ray_loss: self.queue.ray_output(n)?,
            density: self.grad_density.download()?,
            sh: self.grad_sh.download()?,
            background: self.queue.take_background_grad()?,
            counts: self.read_stats()?,
        };
        let grads = [&self.grad_density, &self.grad_sh];
        self.queue.clear_gradients(&grads, self.allocated())?;
        Ok(g)
    }

    fn render(&mut self, rays: &[f32], stop_thresh: f32) -> Result<(Vec<f32>, PlenoxelCounts)> {
        self.queue.settle()?;
        let n = rays.len() / 6;
        let mp = march_params(&self.meta, stop_thresh);
        let (mut b, io) = self.begin_render(rays)?;
        self.record_occupancy(&mut b)?;
        b.dispatch_1d(
            &kernels::plenoxel_fwd::INFO,
            &kernels::plenoxel_fwd::Push {
                links: self.links.address(),
                density: self.density.address(),
                sh: self.sh.address(),
                occ: self.occ.address(),
                rays: io.rays,
                rgb: io.out,
                step: self.queue.step.address(),
                bg: self.queue.bg.address(),
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
        Ok((self.queue.ray_output(3 * n)?, self.read_stats()?))
    }

    fn max_weights(&mut self, rays: &[f32], stop_thresh: f32) -> Result<Vec<f32>> {
        self.queue.settle()?;
        let n = rays.len() / 6;
        let mp = march_params(&self.meta, stop_thresh);
        let out = self.queue.gpu().zeros::<u32>(self.allocated())?;
        let (mut b, io) = self.begin_render(rays)?;
        self.record_occupancy(&mut b)?;
        b.dispatch_1d(
            &kernels::plenoxel_weights::INFO,
            &kernels::plenoxel_weights::Push {
                links: self.links.address(),
                density: self.density.address(),
                sh: self.sh.address(),
                occ: self.occ.address(),
                rays: io.rays,
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

    fn shape(&self) -> ([u32; 3], usize) {
        (self.meta.res, self.allocated())
    }
}

/// A step's figures from its slot: the squared-error sum, the counters.
impl SlotFigures for PlenoxelsStepStats {
    fn read(readback: &Readback, slot: usize, n: usize) -> Result<Self> {
        let sum: Vec<f32> = readback.part(slot, 0)?;
        Ok(PlenoxelsStepStats {
            mse: sum[0] as f64 / (3 * n.max(1)) as f64,
            counts: readback.part::<PlenoxelCounts>(slot, 1)?[0],
            ..Default::default()
        })
    }

    fn set_times(&mut self, device_ns: f64, host: StepTimes) {
        self.device_ns = device_ns;
        self.host = host;
    }
}
