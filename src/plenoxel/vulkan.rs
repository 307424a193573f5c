//! The Vulkan stage-1 backend: grid, gradients, optimiser state and the training views live in
//! device buffers; a training step is one batch (step reset → sample_rays when the batch is drawn
//! on the device → the kernels of the step's [`PlenoxelPlan`], in its order) and one submission.

use super::plan::{PlenoxelPass, PlenoxelPlan, TvField};
use super::{
    march_params, Gradients, PlenoxelsBackend, PlenoxelsStage, PlenoxelsStepParams,
    PlenoxelsStepStats,
};
use crate::abi::buffers::PlenoxelParams;
use crate::abi::buffers::StepHeader;
use crate::abi::rays::SampledRays;
use crate::abi::step::step_record;
use crate::abi::train::RmsProp;
use crate::gpu::{
    record_background_step, record_tv, Batch, BatchRays, Gpu, GpuBuffer, PhaseClock, Readback,
    SlotFigures, TrainRays,
};
use crate::grid::Grid;
use crate::kernels;
use crate::math::plenoxel::{occ_dims, LossWeights, PlenoxelCounts, OCC_SHIFT};
use crate::stage::{QueuedBackend, QueuedGrid, StateArrays};
use anyhow::Result;

/// Where σ and SH sit in the grid's arrays (the order of `PlenoxelsStage::STATE_NAMES`).
const DENSITY: usize = 0;
const SH: usize = 1;

/// Device-resident stage-1 state.
pub struct VulkanPlenoxels {
    /// The queue (per ray 3 floats of output, rgb, for a render, the squared error, 1 float,
    /// for training; per step a slot with the squared-error sum and the counters) and the grid
    /// (σ, SH). First, so that dropping the backend waits for the steps before any buffer they
    /// use is freed.
    core: QueuedGrid<PlenoxelsStage>,
    occ: GpuBuffer,
    /// plenoxel_train's params buffer (written in each training batch's command stream).
    params: GpuBuffer,
}

impl VulkanPlenoxels {
    pub fn new(gpu: &Gpu, grid: Grid) -> Result<Self> {
        let n = grid.allocated();
        let nb = occ_dims(grid.res, OCC_SHIFT);
        // Per step: the squared-error sum (one float), the counters.
        let parts = [4, std::mem::size_of::<PlenoxelCounts>() as u64];
        let step = step_record(n, &[]);
        Ok(VulkanPlenoxels {
            core: QueuedGrid::new(gpu, grid, &step, 3 * std::mem::size_of::<f32>(), &parts)?,
            occ: gpu.zeros::<u32>((nb[0] * nb[1] * nb[2]) as usize)?,
            params: gpu.host_to_device::<PlenoxelParams>(1)?,
        })
    }

    fn record_occupancy(&self, b: &mut Batch) -> Result<()> {
        let nb = occ_dims(self.core.meta.res, OCC_SHIFT);
        b.dispatch_1d(
            &kernels::occupancy::INFO,
            &kernels::occupancy::Push {
                links: self.core.bufs.links.address(),
                density: self.core.bufs.values[DENSITY].address(),
                occ: self.occ.address(),
                res: self.core.meta.res,
                ..Default::default()
            },
            nb[0] * nb[1] * nb[2],
        )
    }

    fn read_stats(&self) -> Result<PlenoxelCounts> {
        Ok(self.core.queue.header()?.stats)
    }

    /// Record the sparse RMSProp step over the vertices touched this step.
    fn record_rmsprop(&self, b: &mut Batch, p: &RmsProp) -> Result<()> {
        self.core.queue.record_optim_args(b)?;
        b.dispatch_indirect(
            &kernels::rmsprop_sparse::INFO,
            &kernels::rmsprop_sparse::Push {
                density: self.core.bufs.values[DENSITY].address(),
                sh: self.core.bufs.values[SH].address(),
                grad_density: self.core.bufs.grads[DENSITY].address(),
                grad_sh: self.core.bufs.grads[SH].address(),
                state_density: self.core.bufs.states[DENSITY].address(),
                state_sh: self.core.bufs.states[SH].address(),
                step: self.core.queue.step.address(),
                lr_sigma: p.lr_sigma,
                lr_sh: p.lr_sh,
                beta: p.beta,
                eps: p.eps,
            },
            &self.core.queue.args,
        )
    }

    /// Upload `rays` and start a batch with the step reset, for a render or a pass that reads
    /// no targets.
    fn begin_render(&mut self, rays: &[f32]) -> Result<(Batch, BatchRays)> {
        self.core
            .queue
            .begin_host(rays, None, &mut PhaseClock::start(), &[])
    }

    /// Write the params buffer for a training pass over `n` rays (in the command stream) and
    /// record the fused train kernel (gradients += data term).
    fn record_train(
        &self,
        b: &mut Batch,
        stop_thresh: f32,
        loss: LossWeights,
        rays: BatchRays,
        n: usize,
    ) -> Result<()> {
        let mp = march_params(&self.core.meta, stop_thresh);
        b.update(
            &self.params,
            0,
            &[PlenoxelParams {
                scale: mp.scale,
                offset: mp.offset,
                stop_thresh,
                grad_scale: loss.grad_scale,
                sparsity: loss.sparsity,
            }],
        )?;
        b.dispatch_1d(
            &kernels::plenoxel_train::INFO,
            &kernels::plenoxel_train::Push {
                links: self.core.bufs.links.address(),
                density: self.core.bufs.values[DENSITY].address(),
                sh: self.core.bufs.values[SH].address(),
                occ: self.occ.address(),
                rays: rays.rays,
                targets: rays.targets,
                grad_density: self.core.bufs.grads[DENSITY].address(),
                grad_sh: self.core.bufs.grads[SH].address(),
                ray_loss: rays.out,
                step: self.core.queue.step.address(),
                params: self.params.address(),
                bg: self.core.queue.bg.address(),
                res: self.core.meta.res,
                n_rays: n as u32,
            },
            n as u32,
        )
    }

    /// The last sampled batch of `n` rays.
    pub fn sampled_batch(&self, n: usize) -> Result<SampledRays> {
        self.core.queue.sampled_batch(n)
    }
}

impl QueuedBackend<PlenoxelsStage> for VulkanPlenoxels {
    type Plan = PlenoxelPlan;

    fn core(&self) -> &QueuedGrid<PlenoxelsStage> {
        &self.core
    }

    fn core_mut(&mut self) -> &mut QueuedGrid<PlenoxelsStage> {
        &mut self.core
    }

    fn plan_step(&mut self, p: &PlenoxelsStepParams, n: usize) -> Result<PlenoxelPlan> {
        PlenoxelPlan::step(p, self.core.meta.res, n, self.core.queue.bg_learned)
    }

    /// The step reset alone: the kernels' counters sit in the step record.
    fn begin(&mut self, src: TrainRays, clock: &mut PhaseClock) -> Result<(Batch, BatchRays)> {
        self.core.queue.begin(src, clock, &[])
    }

    fn record_plan(
        &self,
        b: &mut Batch,
        plan: &PlenoxelPlan,
        rays: BatchRays,
        n: usize,
    ) -> Result<()> {
        let core = &self.core;
        for pass in plan.passes() {
            match pass {
                PlenoxelPass::Occupancy => self.record_occupancy(b)?,
                PlenoxelPass::Train { stop_thresh, loss } => {
                    self.record_train(b, *stop_thresh, *loss, rays, n)?
                }
                PlenoxelPass::Tv { field, chunk } => {
                    let i = match field {
                        TvField::Density => DENSITY,
                        TvField::Sh => SH,
                    };
                    let (data, grad) = (&core.bufs.values[i], &core.bufs.grads[i]);
                    record_tv(b, &core.bufs.links, data, grad, &core.queue.step, chunk)?
                }
                PlenoxelPass::RmsProp(h) => self.record_rmsprop(b, h)?,
                PlenoxelPass::Background(s) => {
                    let q = &core.queue;
                    record_background_step(b, &q.bg, q.spheres.as_ref(), &q.step, s)?
                }
            }
        }
        Ok(())
    }

    /// The squared error summed on the device, the counters copied.
    fn record_figures(&self, b: &mut Batch, slot: usize, n: usize) -> Result<()> {
        let q = &self.core.queue;
        q.record_loss_sum(b, slot, n, 1, 1)?;
        let stats = std::mem::offset_of!(StepHeader, stats) as u64;
        q.readback.copy(b, slot, 1, &q.step, stats);
        Ok(())
    }

    fn fresh(&self, grid: Grid) -> Result<Self> {
        VulkanPlenoxels::new(self.core.queue.gpu(), grid)
    }
}

impl PlenoxelsBackend for VulkanPlenoxels {
    fn gradients(
        &mut self,
        rays: &[f32],
        targets: &[f32],
        stop_thresh: f32,
        sparsity: f32,
    ) -> Result<Gradients> {
        let n = rays.len() / 6;
        let plan = PlenoxelPlan::gradients(stop_thresh, sparsity, n);
        self.run_plan(&plan, rays, targets, None)?;
        let [density, sh] = StateArrays::from_arrays(self.core.bufs.take_grads(&self.core.queue)?)?;
        Ok(Gradients {
            ray_loss: self.core.queue.ray_output(n)?,
            density,
            sh,
            background: self.core.queue.take_background_grad()?,
            spheres: self.core.queue.take_sphere_grad()?,
            counts: self.read_stats()?,
        })
    }

    fn render(&mut self, rays: &[f32], stop_thresh: f32) -> Result<(Vec<f32>, PlenoxelCounts)> {
        self.core.queue.settle()?;
        let n = rays.len() / 6;
        let mp = march_params(&self.core.meta, stop_thresh);
        let (mut b, io) = self.begin_render(rays)?;
        self.record_occupancy(&mut b)?;
        b.dispatch_1d(
            &kernels::plenoxel_fwd::INFO,
            &kernels::plenoxel_fwd::Push {
                links: self.core.bufs.links.address(),
                density: self.core.bufs.values[DENSITY].address(),
                sh: self.core.bufs.values[SH].address(),
                occ: self.occ.address(),
                rays: io.rays,
                rgb: io.out,
                step: self.core.queue.step.address(),
                bg: self.core.queue.bg.address(),
                res: self.core.meta.res,
                scale: mp.scale,
                offset: mp.offset,
                n_rays: n as u32,
                stop_thresh,
                ..Default::default()
            },
            n as u32,
        )?;
        b.submit()?;
        Ok((self.core.queue.ray_output(3 * n)?, self.read_stats()?))
    }

    fn max_weights(&mut self, rays: &[f32], stop_thresh: f32) -> Result<Vec<f32>> {
        self.core.queue.settle()?;
        let n = rays.len() / 6;
        let mp = march_params(&self.core.meta, stop_thresh);
        let out = self.core.queue.gpu().zeros::<u32>(self.core.bufs.rows())?;
        let (mut b, io) = self.begin_render(rays)?;
        self.record_occupancy(&mut b)?;
        b.dispatch_1d(
            &kernels::plenoxel_weights::INFO,
            &kernels::plenoxel_weights::Push {
                links: self.core.bufs.links.address(),
                density: self.core.bufs.values[DENSITY].address(),
                sh: self.core.bufs.values[SH].address(),
                occ: self.occ.address(),
                rays: io.rays,
                max_weight: out.address(),
                res: self.core.meta.res,
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
        (self.core.meta.res, self.core.bufs.rows())
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
}
