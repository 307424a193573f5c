//! Stage-2 (αSurf) compute backends: one interface, a CPU implementation running the kernels'
//! twins and a Vulkan implementation running the GLSL kernels (one submission per step).

mod cpu;
pub mod delta_tv;
pub mod normal_reg;
pub mod plan;
pub mod rmsprop;
pub mod skip;
mod vulkan;

pub use cpu::CpuSurface;
pub use vulkan::{surf_params, SurfaceGradients, VulkanSurface};

use crate::abi::buffers::Background;
use crate::abi::buffers::SurfCounts;
use crate::abi::buffers::TrainCounts;
use crate::abi::regularisers::DeltaTvChunk;
use crate::abi::regularisers::OpacityChunk;
use crate::abi::regularisers::TvChunk;
use crate::abi::train::SurfaceLoss;
use crate::data::TrainViews;
use crate::grid::surface::SurfaceGrid;
use crate::math::surface::SurfaceParams;
use crate::math::surface::Truncation;
use anyhow::Result;

/// The per-vertex regularisers of one step (method.md §3.4); `None` switches a term off.
#[derive(Clone, Copy, Debug, Default)]
pub struct SurfaceRegs {
    /// Lδ: TV on δ over a chunk of the vertex rows (every row in the paper preset), forward
    /// differences scaled by N/256 (`delta_tv_chunk`).
    pub delta_tv: Option<DeltaTvChunk>,
    /// TVα on σα over a random slot chunk (`opacity_tv_chunk`).
    pub opacity_tv: Option<TvChunk>,
    /// Lα = λ Σ log σα (σα > 0) over a row chunk.
    pub opacity_log: Option<OpacityChunk>,
    /// Ln1, Ln2 on the cells of a chunk of vertex rows: (start, count, λ1, λ2).
    pub normals: Option<(u32, u32, f32, f32)>,
}

/// Everything one stage-2 step needs besides the rays.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceStepParams {
    pub lr_delta: f32,
    pub lr_opacity: f32,
    pub lr_sh: f32,
    pub beta: f32,
    pub eps: f32,
    /// Truncated compositing (a ≤ 8).
    pub truncation: Truncation,
    pub stop_thresh: f32,
    /// Per-ray entropy and depth-consistency weights (the batch mean is applied by the backend).
    pub lambda_h: f32,
    pub lambda_c: f32,
    pub regs: SurfaceRegs,
    /// RMSProp rate of a learned background (`background_step`; unused when it is fixed).
    pub lr_bg: f32,
}

use crate::abi::consts::OPACITY_REG_ROWS;

/// Invocations of surface_opacity_reg for chunk `c`.
pub fn opacity_reg_invocations(c: &OpacityChunk) -> u32 {
    c.count.min(c.rows).div_ceil(OPACITY_REG_ROWS)
}

/// What a step reports back.
#[derive(Clone, Copy, Debug, Default)]
pub struct SurfaceStepStats {
    /// Mean squared error over the batch's rays and channels.
    pub mse: f64,
    /// Means over rays of the entropy and depth-consistency terms (unweighted).
    pub entropy: f64,
    pub consistency: f64,
    /// Weighted losses of the regularisers Lα and Ln (the TV terms are not evaluated).
    pub reg_loss: f64,
    /// Counters of the training pass (see `abi::buffers::TrainCounts`).
    pub counts: TrainCounts,
    /// Device time of the step's kernels in ns (0 on the CPU backend).
    pub device_ns: f64,
    /// Host time of the step by phase (upload to readback on Vulkan, compute on the CPU).
    pub host: crate::gpu::StepTimes,
}

/// The optimiser's running averages: δ, σα, SH.
pub type SurfaceState = [Vec<f32>; 3];

/// What [`SurfaceBackend::with_state`] calls: the grid and the running averages (δ, σα, SH).
pub type SurfaceStateFn<'a> = dyn FnMut(&SurfaceGrid, [&[f32]; 3]) -> Result<()> + 'a;

/// A stage-2 compute backend holding the surface grid and its optimiser state.
pub trait SurfaceBackend {
    /// Backend name for logs ("vulkan" or "cpu").
    fn name(&self) -> &'static str;
    /// One optimisation step on a batch: `rays` 6 floats per ray, `targets` 3 per ray.
    fn step(
        &mut self,
        rays: &[f32],
        targets: &[f32],
        p: &SurfaceStepParams,
    ) -> Result<SurfaceStepStats>;
    /// One optimisation step on the batch of `n` rays drawn from `views` with `seed`
    /// (`cpu::sample_rays`): the CPU backend draws it with the twin on the host; the Vulkan
    /// backend draws it on the device, from views it uploads once, and returns once the step is
    /// submitted (the device may still run it). Its figures come with [`Self::take_stats`].
    fn step_sampled(
        &mut self,
        views: &TrainViews,
        seed: u64,
        n: usize,
        p: &SurfaceStepParams,
    ) -> Result<()>;
    /// The figures of every `step_sampled` step since the last call, in order (waits for the
    /// steps still running). A backend keeps at most [`crate::gpu::STEP_SLOTS`] steps' figures
    /// on the device and reads them into host memory when that many have not been taken.
    fn take_stats(&mut self) -> Result<Vec<SurfaceStepStats>>;
    /// Render rays (composited on the background): 3 floats per ray, and the counters of
    /// `surface_fwd`.
    fn render(
        &mut self,
        rays: &[f32],
        truncation: Truncation,
        stop_thresh: f32,
    ) -> Result<(Vec<f32>, SurfCounts)>;
    /// The current grid.
    fn grid(&self) -> Result<SurfaceGrid>;
    /// RMSProp running averages.
    fn optimizer_state(&self) -> Result<SurfaceState>;
    /// Bytes of a copy of the grid and the running averages (what a checkpoint holds).
    fn state_bytes(&self) -> u64;
    /// Call `f` with the grid and the running averages (δ, σα, SH): borrowed where the backend
    /// holds them in host memory (checkpoints of large grids copy nothing), else downloaded.
    fn with_state(&self, f: &mut SurfaceStateFn) -> Result<()> {
        let [sd, so, ss] = self.optimizer_state()?;
        f(&self.grid()?, [&sd, &so, &ss])
    }
    /// Replace grid and optimiser state (after pruning, or when resuming); the background stays.
    fn load(&mut self, grid: SurfaceGrid, state: Option<SurfaceState>) -> Result<()>;
    /// The background with its optimiser state (white and fixed unless set).
    fn background(&self) -> Result<Background>;
    /// Replace the background (colour, whether it is learned, its optimiser state).
    fn set_background(&mut self, bg: Background) -> Result<()>;
}

/// Passes between rebuilds of the block masks the walks skip with (see [`BlockRefresh`]).
pub const BLOCK_REFRESH_STEPS: f32 = 16.0;

/// When the block masks (`surface_blocks`) must be rebuilt. Masks built with margin M stay exact
/// (a block whose widened δ range holds no level cannot hold a hit) while δ has moved by at most M
/// since the build. RMSProp moves a parameter by at most lr/√(1 − β) per update (after any update
/// with g ≠ 0, r ≥ (1 − β)g²), so each update adds that bound for δ's rate; the masks are rebuilt,
/// with room for [`BLOCK_REFRESH_STEPS`] more updates at the current rate, once the drift bound
/// exceeds the margin.
#[derive(Clone, Copy, Debug, Default)]
pub struct BlockRefresh {
    margin: f32,
    drift: f32,
    valid: bool,
}

impl BlockRefresh {
    /// Bound on one RMSProp update of a parameter with rate `lr` (1 % slack for rounding).
    fn step_bound(lr: f32, beta: f32) -> f32 {
        1.01 * lr / (1.0 - beta).max(1e-6).sqrt()
    }

    /// Before a pass that walks: `Some(margin)` when the masks must be rebuilt with that margin
    /// (`lr_delta`, `beta`: the coming updates' rate; 0 for a render).
    pub fn before_pass(&mut self, lr_delta: f32, beta: f32) -> Option<f32> {
        if self.valid && self.drift <= self.margin {
            return None;
        }
        // A diverging rate gives an infinite bound: every block with a vertex stays live.
        self.margin = (BLOCK_REFRESH_STEPS * Self::step_bound(lr_delta, beta)).min(f32::MAX);
        self.drift = 0.0;
        self.valid = true;
        Some(self.margin)
    }

    /// After an optimiser update of δ with rate `lr_delta`.
    pub fn after_update(&mut self, lr_delta: f32, beta: f32) {
        self.drift += Self::step_bound(lr_delta, beta);
    }
}

/// Ray → grid mapping and rendering parameters of a surface grid, composited on `background`.
pub fn surface_params(
    g: &SurfaceGrid,
    truncation: Truncation,
    stop_thresh: f32,
    background: [f32; 3],
) -> SurfaceParams {
    SurfaceParams {
        scale: std::array::from_fn(|i| g.res[i] as f32 / (2.0 * g.radius[i])),
        offset: std::array::from_fn(|i| {
            (0.5 - g.center[i] / (2.0 * g.radius[i])) * g.res[i] as f32 - 0.5
        }),
        levels: g.levels.clone(),
        truncation,
        stop_thresh,
        background,
    }
}

/// The weights of a batch of `n` rays: dL/dC = 2(C − c)/(3n) for the mean squared error; the
/// entropy and consistency terms are means over rays too.
pub fn batch_loss(n: usize, p: &SurfaceStepParams) -> SurfaceLoss {
    let n = n.max(1) as f32;
    SurfaceLoss {
        grad_scale: 2.0 / (3.0 * n),
        lambda_h: p.lambda_h / n,
        lambda_c: p.lambda_c / n,
    }
}
