//! The Vulkan stage-2 backend: grid, gradients, optimiser state and the training views live in
//! device buffers; a training step is one batch and one submission: step reset → sample_rays
//! (when the batch is drawn on the device) → the kernels of the step's [`SurfacePlan`], in its
//! order (the skip structure through surface_live_cells, surface_blocks and the radius passes;
//! surface_train; Lδ through the two surface_delta_tv passes, TVα through `tv`, Lα through
//! surface_opacity_reg, Ln1/Ln2 through the three surface_normal_reg_* passes, each over its
//! chunk's window; surface_rmsprop: δ and σα on the rows the regularisers' chunks cover, then
//! (optim_args → indirect) the flagged groups of the touched vertices; background_step).

use super::delta_tv::{record_delta_tv, DeltaTvIo, Q_FLOATS};
use super::normal_reg::{record_normal_reg, NormalRegBuffers, NormalRegIo};
use super::plan::{PlanGrid, SurfacePass, SurfacePlan};
use super::rmsprop::{record_surface_rmsprop, SurfaceOptimIo};
use super::skip::{record_skip_structure, SkipIo};
use super::{
    opacity_reg_invocations, surface_params, BlockRefresh, SurfaceBackend, SurfaceStage,
    SurfaceStepParams, SurfaceStepStats,
};
use crate::abi::buffers::{RayLoss, SurfCounts, SurfOut, SurfParams, TrainCounts};
use crate::abi::consts::LOSS_SUM_FIELDS;
use crate::abi::normal_reg::NormalPrefix;
use crate::abi::regularisers::TvChunk;
use crate::abi::regularisers::{axis_neighbours, forward_reach};
use crate::abi::step::{step_record, STEP_FLAGS};
use crate::abi::train::SurfaceLoss;
use crate::gpu::{
    address_words, record_background_step, record_tv, Batch, BatchRays, Gpu, GpuBuffer, PhaseClock,
    Readback, SlotFigures, TrainRays,
};
use crate::grid::row_slots;
use crate::grid::surface::SurfaceGrid;
use crate::kernels;
use crate::math::surface::SurfaceParams;
use crate::math::surface::Truncation;
use crate::math::surface::SURF_MAX_LEVELS;
use crate::math::surface_blocks::{alloc_box, complete_cells};
use crate::math::surface_blocks::{
    surf_blocks_per_axis, surf_live_words, SURF_BLOCK_SHIFT_VULKAN, SURF_BOX_WORDS,
};
use crate::stage::{QueuedBackend, QueuedGrid, StateArrays};
use anyhow::{ensure, Result};

/// Where δ, σα and SH sit in the grid's arrays (the order of `SurfaceStage::STATE_NAMES`).
const DELTA: usize = 0;
const OPACITY: usize = 1;
const SH: usize = 2;

/// Regulariser values a step writes: Lα, Ln.
const REG_VALUES: usize = 2;

/// The params buffer of `surface_fwd` and `surface_train` for a batch of `n_rays`: the levels
/// zero-padded to [`SURF_MAX_LEVELS`]; `loss` zero for a render.
pub fn surf_params(sp: &SurfaceParams, loss: &SurfaceLoss, n_rays: usize) -> SurfParams {
    let mut levels = [0.0f32; SURF_MAX_LEVELS];
    for (d, &l) in levels.iter_mut().zip(&sp.levels) {
        *d = l;
    }
    SurfParams {
        scale: sp.scale,
        offset: sp.offset,
        a: sp.truncation.a,
        stop_thresh: sp.stop_thresh,
        grad_scale: loss.grad_scale,
        lambda_h: loss.lambda_h,
        lambda_c: loss.lambda_c,
        n_rays: n_rays as u32,
        n_levels: sp.levels.len() as u32,
        levels,
        weights: [0, 0],
        truncation_count: sp.truncation.count.code(),
    }
}

const _: () = assert!(std::mem::size_of::<SurfCounts>() <= std::mem::size_of::<TrainCounts>());

/// The data term of one training pass, read back (see [`VulkanSurface::gradients`]).
pub struct SurfaceGradients {
    pub ray_loss: Vec<RayLoss>,
    pub delta: Vec<f32>,
    pub opacity: Vec<f32>,
    pub sh: Vec<f32>,
    /// Per-vertex touched flags (0/1).
    pub touched: Vec<u32>,
    /// dL/dbg of a learned background (zero when it is fixed).
    pub background: [f32; 3],
    pub counts: TrainCounts,
}

/// Device-resident stage-2 state.
pub struct VulkanSurface {
    /// The queue (per ray `RayLoss`, 16 bytes, of output for training, `SurfOut`, 20 bytes, for
    /// rendering; per step a slot with the loss sums, squared error, entropy and consistency, the
    /// regulariser values and the counters) and the grid (δ, σα, SH; resolution, bounds,
    /// levels). First, so that dropping the backend waits for the steps before any buffer they
    /// use is freed.
    core: QueuedGrid<SurfaceStage>,
    /// Complete-cell bits ([`complete_cells`], `complete_words` words, static), then the walks'
    /// skip structure: as many live-cell words (`surface_live_cells`) and the nb³ block words
    /// (level masks, `surface_blocks`, and empty radii, `surface_block_radius`), rebuilt whenever
    /// δ may have drifted past their margin, and the allocated box (`alloc_box`, static); then
    /// 2·nb³ words of scratch for the radius passes.
    complete: GpuBuffer,
    complete_words: u64,
    /// When the block masks must be rebuilt.
    refresh: BlockRefresh,
    /// Slots [first, last] of the allocated vertices (Lδ's TV needs no other slots).
    allocated_span: (u32, u32),
    /// The params buffer of surface_fwd and surface_train (written in each training batch's
    /// command stream, before a render).
    params: GpuBuffer,
    /// The levels, zero-padded (the skip-structure kernels).
    levels: GpuBuffer,
    /// Counters: `TrainCounts` of surface_train, or `SurfCounts` of surface_fwd (no larger).
    stats: GpuBuffer,
    /// Lδ's axis-neighbour table (6 rows per row), its forward reach in rows
    /// (`forward_reach`), and its per-row directions q (3 floats).
    axis_nbrs: GpuBuffer,
    axis_reach: u32,
    tv_dirs: GpuBuffer,
    /// The normal regulariser's per-grid data (neighbour table, prefix count).
    normal_prefix: NormalPrefix,
    /// The normal regulariser's neighbour table and per-row arrays on the device.
    normal_bufs: NormalRegBuffers,
    /// Regulariser values: Lα, Ln (floats); pairs skipped by Ln (u32).
    reg_loss: GpuBuffer,
    reg_skipped: GpuBuffer,
}

impl VulkanSurface {
    pub fn new(gpu: &Gpu, grid: SurfaceGrid) -> Result<Self> {
        ensure!(
            grid.res[0] == grid.res[1] && grid.res[1] == grid.res[2],
            "the surface renderer needs a cubic grid, got {:?}",
            grid.res
        );
        grid.as_ref().validate()?;
        ensure!(
            grid.levels.len() <= SURF_MAX_LEVELS,
            "at most {SURF_MAX_LEVELS} levels, got {}",
            grid.levels.len()
        );
        let n = grid.delta.len();
        let rows = n.max(1);
        let mut levels = grid.levels.clone();
        levels.resize(SURF_MAX_LEVELS, 0.0);
        let row_slot = row_slots(&grid.links, n);
        let normal_prefix = NormalPrefix::new(&grid.links, &row_slot, grid.res);
        let axis_nbrs = axis_neighbours(&grid.links, &row_slot, grid.res);
        let mut step = step_record(n, &[]);
        step.resize(STEP_FLAGS + 2 * rows, 0);
        let parts = [
            4 * LOSS_SUM_FIELDS as u64,
            4 * REG_VALUES as u64,
            std::mem::size_of::<TrainCounts>() as u64,
        ];
        Ok(VulkanSurface {
            complete: {
                let mut words = complete_cells(&grid.links, grid.res[0]);
                let nb = surf_blocks_per_axis(grid.res[0], SURF_BLOCK_SHIFT_VULKAN) as usize;
                words.resize(2 * words.len() + nb * nb * nb, 0);
                // The allocated box after the block masks: static, written once.
                words.extend(alloc_box(&grid.links, grid.res[0]));
                // Scratch of the radius passes.
                words.resize(words.len() + 2 * nb * nb * nb, 0);
                gpu.upload(&words)?
            },
            complete_words: surf_live_words(grid.res[0]) as u64,
            refresh: BlockRefresh::default(),
            allocated_span: (
                grid.links.iter().position(|&l| l >= 0).unwrap_or(0) as u32,
                grid.links.iter().rposition(|&l| l >= 0).unwrap_or(0) as u32,
            ),
            params: gpu.host_to_device::<SurfParams>(1)?,
            levels: gpu.upload(&levels)?,
            stats: gpu.zeros::<TrainCounts>(1)?,
            axis_nbrs: gpu.upload_nonempty(&axis_nbrs)?,
            axis_reach: forward_reach(&axis_nbrs),
            tv_dirs: gpu.zeros::<f32>(Q_FLOATS * n.max(1))?,
            normal_bufs: NormalRegBuffers::new(gpu, &normal_prefix)?,
            normal_prefix,
            reg_loss: gpu.zeros::<f32>(REG_VALUES)?,
            reg_skipped: gpu.zeros::<u32>(1)?,
            core: QueuedGrid::new(gpu, grid, &step, std::mem::size_of::<SurfOut>(), &parts)?,
        })
    }

    /// The grid as the step plans see it.
    fn plan_grid(&self) -> PlanGrid<'_> {
        PlanGrid {
            res: self.core.meta.res,
            rows: self.core.bufs.rows() as u32,
            normals: &self.normal_prefix,
            delta_reach: self.axis_reach,
        }
    }

    /// Write the params buffer for a training pass over `n` rays (in the command stream) and
    /// record `surface_train`.
    fn record_train(
        &self,
        b: &mut Batch,
        truncation: Truncation,
        stop_thresh: f32,
        loss: &SurfaceLoss,
        io: BatchRays,
        n: usize,
    ) -> Result<()> {
        // The colour is the device's (`bg`); surface_fwd and surface_train read it there.
        let sp = surface_params(&self.core.meta, truncation, stop_thresh, [1.0; 3]);
        let prm = SurfParams {
            weights: address_words(io.weights),
            ..surf_params(&sp, loss, n)
        };
        b.update(&self.params, 0, &[prm])?;
        b.dispatch_1d(
            &kernels::surface_train::INFO,
            &kernels::surface_train::Push {
                links: self.core.bufs.links.address(),
                skip: self.skip_address(),
                delta: self.core.bufs.values[DELTA].address(),
                opacity: self.core.bufs.values[OPACITY].address(),
                sh: self.core.bufs.values[SH].address(),
                params: self.params.address(),
                rays: io.rays,
                targets: io.targets,
                grad_delta: self.core.bufs.grads[DELTA].address(),
                grad_opacity: self.core.bufs.grads[OPACITY].address(),
                grad_sh: self.core.bufs.grads[SH].address(),
                out_rays: io.out,
                stats: self.stats.address(),
                step: self.core.queue.step.address(),
                bg: self.core.queue.bg.address(),
                n: self.core.meta.res[0],
                block_shift: SURF_BLOCK_SHIFT_VULKAN,
            },
            n as u32,
        )
    }

    /// Record TVα. Its chunk is dispatched over its intersection with the span of allocated
    /// slots: a slot outside it holds no vertex, and every term of the chunk (a vertex and its
    /// forward neighbours) lies inside it, so the gradient is the whole chunk's.
    fn record_opacity_tv(&self, b: &mut Batch, c: &TvChunk) -> Result<()> {
        let res = self.core.meta.res;
        let (first, last) = self.allocated_span;
        let start = c.start.max(first);
        let end = c.start.saturating_add(c.count).min(last + 1);
        if start >= end {
            return Ok(());
        }
        let chunk = TvChunk {
            res,
            start,
            count: end - start,
            channels: 1,
            ..*c
        };
        record_tv(
            b,
            &self.core.bufs.links,
            &self.core.bufs.values[OPACITY],
            &self.core.bufs.grads[OPACITY],
            &self.core.queue.step,
            &chunk,
        )
    }

    /// Device address of the skip structure (after the complete-cell bits).
    fn skip_address(&self) -> u64 {
        self.complete.address() + 4 * self.complete_words
    }

    /// Record `surface_live_cells` and `surface_blocks`: the skip structure of the current δ
    /// (live-cell bits, and level masks per 4³-cell block), ranges widened by `margin` (see
    /// `BlockRefresh`), so the walks skip only cells and blocks that cannot hold a hit.
    fn record_blocks(&self, b: &mut Batch, margin: f32) -> Result<()> {
        let nb = surf_blocks_per_axis(self.core.meta.res[0], SURF_BLOCK_SHIFT_VULKAN) as u64;
        record_skip_structure(
            b,
            &SkipIo {
                complete: self.complete.address(),
                links: self.core.bufs.links.address(),
                delta: self.core.bufs.values[DELTA].address(),
                levels: self.levels.address(),
                skip: self.skip_address(),
                scratch: self.skip_address()
                    + 4 * (self.complete_words + nb * nb * nb + SURF_BOX_WORDS as u64),
                n: self.core.meta.res[0],
                n_levels: self.core.meta.levels.len() as u32,
                shift: SURF_BLOCK_SHIFT_VULKAN,
            },
            margin,
        )
    }

    /// The addresses Lδ's passes work on.
    fn delta_tv_io(&self) -> DeltaTvIo {
        DeltaTvIo {
            nbr: self.axis_nbrs.address(),
            delta: self.core.bufs.values[DELTA].address(),
            q: self.tv_dirs.address(),
            grad: self.core.bufs.grads[DELTA].address(),
        }
    }

    fn read_train_counts(&self) -> Result<TrainCounts> {
        Ok(self.stats.download_range::<TrainCounts>(0, 1)?[0])
    }

    /// The training pass alone (no regulariser, no update) on rays with optional per-ray
    /// importance `weights`: per-ray losses, the gradients, the touched flags and the counters;
    /// gradients and flags are cleared afterwards.
    pub fn gradients(
        &mut self,
        rays: &[f32],
        targets: &[f32],
        weights: Option<&[f32]>,
        p: &SurfaceStepParams,
    ) -> Result<SurfaceGradients> {
        let n = rays.len() / 6;
        let mut refresh = self.refresh;
        let plan = SurfacePlan::gradients(p, n, &mut refresh)?;
        self.run_plan(&plan, rays, targets, weights)?;
        self.refresh = refresh;
        let (q, bufs) = (&self.core.queue, &self.core.bufs);
        // The touched flags before the gradients are taken: taking them clears the flags.
        let touched = q.step.download_range(STEP_FLAGS, bufs.rows())?;
        let [delta, opacity, sh] = StateArrays::from_arrays(bufs.take_grads(q)?)?;
        Ok(SurfaceGradients {
            ray_loss: q.ray_output(n)?,
            delta,
            opacity,
            sh,
            touched,
            background: q.take_background_grad()?,
            counts: self.read_train_counts()?,
        })
    }

    /// Number of vertices touched by the last step (read from the step record).
    pub fn last_touched(&self) -> Result<u32> {
        self.core.queue.settle()?;
        Ok(self.core.queue.header()?.count)
    }
}

impl QueuedBackend<SurfaceStage> for VulkanSurface {
    type Plan = SurfacePlan;

    fn core(&self) -> &QueuedGrid<SurfaceStage> {
        &self.core
    }

    fn core_mut(&mut self) -> &mut QueuedGrid<SurfaceStage> {
        &mut self.core
    }

    /// The plan, with the skip structure counted as rebuilt where the plan rebuilds it and δ's
    /// drift by the step's update added.
    fn plan_step(&mut self, p: &SurfaceStepParams, n: usize) -> Result<SurfacePlan> {
        let mut refresh = self.refresh;
        let learned = self.core.queue.bg_learned;
        let plan = SurfacePlan::step(p, &self.plan_grid(), n, learned, &mut refresh)?;
        self.refresh = refresh;
        self.refresh.after_update(p.lr_delta, p.beta);
        Ok(plan)
    }

    /// The step reset with the training pass's counters and the regulariser values cleared.
    fn begin(&mut self, src: TrainRays, clock: &mut PhaseClock) -> Result<(Batch, BatchRays)> {
        let counters = [&self.stats, &self.reg_loss, &self.reg_skipped];
        self.core.queue.begin(src, clock, &counters)
    }

    fn record_plan(
        &self,
        b: &mut Batch,
        plan: &SurfacePlan,
        rays: BatchRays,
        n: usize,
    ) -> Result<()> {
        for pass in plan.passes() {
            match pass {
                SurfacePass::Blocks { margin } => self.record_blocks(b, *margin)?,
                SurfacePass::Train {
                    truncation,
                    stop_thresh,
                    loss,
                } => self.record_train(b, *truncation, *stop_thresh, loss, rays, n)?,
                SurfacePass::DeltaTv(c) => {
                    record_delta_tv(b, &self.delta_tv_io(), c, self.axis_reach)?
                }
                SurfacePass::OpacityTv(c) => self.record_opacity_tv(b, c)?,
                SurfacePass::OpacityLog(c) => b.dispatch_1d(
                    &kernels::surface_opacity_reg::INFO,
                    &kernels::surface_opacity_reg::Push {
                        opacity: self.core.bufs.values[OPACITY].address(),
                        grad: self.core.bufs.grads[OPACITY].address(),
                        loss: self.reg_loss.address(),
                        rows: c.rows,
                        start: c.start,
                        count: c.count,
                        lambda: c.lambda,
                    },
                    opacity_reg_invocations(c),
                )?,
                SurfacePass::Normals(c) => {
                    let io = NormalRegIo {
                        delta: self.core.bufs.values[DELTA].address(),
                        grad: self.core.bufs.grads[DELTA].address(),
                        step: self.core.queue.step.address(),
                        loss: self.reg_loss.address() + 4,
                        skipped: self.reg_skipped.address(),
                    };
                    record_normal_reg(b, &self.normal_bufs, &io, c)?;
                }
                SurfacePass::RmsProp(h) => {
                    let io = SurfaceOptimIo {
                        params: std::array::from_fn(|i| self.core.bufs.values[i].address()),
                        grads: std::array::from_fn(|i| self.core.bufs.grads[i].address()),
                        states: std::array::from_fn(|i| self.core.bufs.states[i].address()),
                    };
                    let q = &self.core.queue;
                    record_surface_rmsprop(b, &io, &q.step, &q.args, h)?;
                }
                SurfacePass::Background(s) => {
                    let q = &self.core.queue;
                    record_background_step(b, &q.bg, q.spheres.as_ref(), &q.step, s)?
                }
            }
        }
        Ok(())
    }

    /// Per-ray losses summed on the device, the regulariser values and the counters copied.
    fn record_figures(&self, b: &mut Batch, slot: usize, n: usize) -> Result<()> {
        let q = &self.core.queue;
        let stride = (std::mem::size_of::<RayLoss>() / 4) as u32;
        q.record_loss_sum(b, slot, n, stride, 3)?;
        q.readback.copy(b, slot, 1, &self.reg_loss, 0);
        q.readback.copy(b, slot, 2, &self.stats, 0);
        Ok(())
    }

    fn fresh(&self, grid: SurfaceGrid) -> Result<Self> {
        VulkanSurface::new(self.core.queue.gpu(), grid)
    }
}

impl SurfaceBackend for VulkanSurface {
    fn render(
        &mut self,
        rays: &[f32],
        truncation: Truncation,
        stop_thresh: f32,
    ) -> Result<(Vec<f32>, SurfCounts)> {
        self.core.queue.settle()?;
        let n = rays.len() / 6;
        let sp = surface_params(&self.core.meta, truncation, stop_thresh, [1.0; 3]);
        let no_loss = SurfaceLoss {
            grad_scale: 0.0,
            lambda_h: 0.0,
            lambda_c: 0.0,
        };
        self.params.write(&[surf_params(&sp, &no_loss, n)])?;
        ensure!(
            rays.len().is_multiple_of(6),
            "rays must be 6 floats each, got {} floats",
            rays.len()
        );
        let counters = [&self.stats, &self.reg_loss, &self.reg_skipped];
        let clock = &mut PhaseClock::start();
        let (mut b, io) = self.core.queue.begin_host(rays, None, clock, &counters)?;
        if let Some(margin) = self.refresh.before_pass(0.0, 0.0) {
            self.record_blocks(&mut b, margin)?;
        }
        b.dispatch_1d(
            &kernels::surface_fwd::INFO,
            &kernels::surface_fwd::Push {
                links: self.core.bufs.links.address(),
                delta: self.core.bufs.values[DELTA].address(),
                opacity: self.core.bufs.values[OPACITY].address(),
                sh: self.core.bufs.values[SH].address(),
                params: self.params.address(),
                rays: io.rays,
                out_rays: io.out,
                stats: self.stats.address(),
                bg: self.core.queue.bg.address(),
                n: self.core.meta.res[0],
                blocks: self.skip_address(),
                block_skip: 1,
                block_shift: SURF_BLOCK_SHIFT_VULKAN,
                ..Default::default()
            },
            n as u32,
        )?;
        b.submit()?;
        let out: Vec<SurfOut> = self.core.queue.ray_output(n)?;
        let counts = self.stats.download_range::<SurfCounts>(0, 1)?[0];
        Ok((out.iter().flat_map(|o| o.rgb).collect(), counts))
    }
}

/// A step's figures from its slot: the loss sums, the regulariser values, the counters.
impl SlotFigures for SurfaceStepStats {
    fn read(readback: &Readback, slot: usize, n: usize) -> Result<Self> {
        let sums: Vec<f32> = readback.part(slot, 0)?;
        let reg: Vec<f32> = readback.part(slot, 1)?;
        let nf = n.max(1) as f64;
        Ok(SurfaceStepStats {
            mse: sums[0] as f64 / (3.0 * nf),
            entropy: sums[1] as f64 / nf,
            consistency: sums[2] as f64 / nf,
            reg_loss: reg.iter().map(|&x| x as f64).sum(),
            counts: readback.part::<TrainCounts>(slot, 2)?[0],
            ..Default::default()
        })
    }
}
