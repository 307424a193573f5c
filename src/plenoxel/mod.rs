//! Stage-1 (Plenoxels) compute backends: one interface, a Vulkan implementation running the GLSL
//! kernels (one submission per training step) and a CPU implementation running their twins.

mod cpu;
pub mod plan;
mod vulkan;

pub use cpu::CpuPlenoxels;
pub use vulkan::VulkanPlenoxels;

use crate::abi::buffers::Background;
use crate::data::TrainViews;
use crate::grid::checkpoint::state_bytes;
use crate::grid::{Grid, SH_DIM};
use crate::math::plenoxel::MarchParams;
use crate::math::plenoxel::PlenoxelCounts;
use anyhow::Result;

/// TV regularisation of one step: a contiguous chunk of vertex slots and the two weights.
#[derive(Clone, Copy, Debug)]
pub struct TvParams {
    pub start: u32,
    pub count: u32,
    pub lambda_sigma: f32,
    pub lambda_sh: f32,
}

/// Everything one training step needs besides the rays.
#[derive(Clone, Copy, Debug)]
pub struct StepParams {
    pub lr_sigma: f32,
    pub lr_sh: f32,
    pub beta: f32,
    pub eps: f32,
    pub stop_thresh: f32,
    pub tv: Option<TvParams>,
    /// RMSProp rate of a learned background (`background_step`; unused when it is fixed).
    pub lr_bg: f32,
}

/// What a step reports back.
#[derive(Clone, Copy, Debug, Default)]
pub struct StepStats {
    /// Mean squared error over the batch's rays and channels.
    pub mse: f64,
    /// Samples shaded, evaluated at σ ≤ ε, skipped by the occupancy volume; gradient atomic adds.
    pub counts: PlenoxelCounts,
    /// Device time of the step's kernels in ns (0 on the CPU backend).
    pub device_ns: f64,
    /// Host time of the step by phase (upload to readback on Vulkan, compute on the CPU).
    pub host: crate::gpu::StepTimes,
}

/// Output of `Plenoxels::gradients`.
#[derive(Clone, Debug, Default)]
pub struct Gradients {
    pub ray_loss: Vec<f32>,
    pub density: Vec<f32>,
    pub sh: Vec<f32>,
    /// dL/dbg of a learned background (zero when it is fixed).
    pub background: [f32; 3],
    pub counts: PlenoxelCounts,
}

/// What [`Plenoxels::with_state`] calls: the grid and the running averages (σ, SH).
pub type StateFn<'a> = dyn FnMut(&Grid, [&[f32]; 2]) -> Result<()> + 'a;

/// A stage-1 compute backend holding the grid and its optimiser state.
pub trait Plenoxels {
    /// Backend name for logs ("vulkan" or "cpu").
    fn name(&self) -> &'static str;
    /// One optimisation step on a batch: `rays` 6 floats per ray, `targets` 3 per ray.
    fn step(&mut self, rays: &[f32], targets: &[f32], p: &StepParams) -> Result<StepStats>;
    /// One optimisation step on the batch of `n` rays drawn from `views` with `seed`
    /// (`cpu::sample_rays`): the CPU backend draws it with the twin on the host; the Vulkan
    /// backend draws it on the device, from views it uploads once, and returns once the step is
    /// submitted (the device may still run it). Its figures come with [`Self::take_stats`].
    /// Stage 1 trains on uniform batches: views with a focus are refused ([`uniform_views`]).
    fn step_sampled(
        &mut self,
        views: &TrainViews,
        seed: u64,
        n: usize,
        p: &StepParams,
    ) -> Result<()>;
    /// The figures of every `step_sampled` step since the last call, in order (waits for the
    /// steps still running). A backend keeps at most [`crate::gpu::STEP_SLOTS`] steps' figures
    /// on the device and reads them into host memory when that many have not been taken.
    fn take_stats(&mut self) -> Result<Vec<StepStats>>;
    /// The data-term gradients of a batch without updating anything: per-ray squared error,
    /// dL/dσ, dL/dSH and, when it is learned, dL/dbg (L = mean squared error over rays and
    /// channels), and the sample counts.
    fn gradients(&mut self, rays: &[f32], targets: &[f32], stop_thresh: f32) -> Result<Gradients>;
    /// Render rays (composited on the background): 3 floats per ray, and the sample counts.
    fn render(&mut self, rays: &[f32], stop_thresh: f32) -> Result<(Vec<f32>, PlenoxelCounts)>;
    /// Max over rays and samples of w·w_trilinear per allocated vertex (pruning weights).
    fn max_weights(&mut self, rays: &[f32], stop_thresh: f32) -> Result<Vec<f32>>;
    /// The current grid.
    fn grid(&self) -> Result<Grid>;
    /// RMSProp running averages (σ, SH).
    fn optimizer_state(&self) -> Result<(Vec<f32>, Vec<f32>)>;
    /// Vertices per axis and allocated vertices of the current grid (nothing copied).
    fn shape(&self) -> ([u32; 3], usize);
    /// Bytes of a copy of the grid and the running averages (what a checkpoint holds).
    fn state_bytes(&self) -> u64 {
        let (res, rows) = self.shape();
        let slots = res.iter().map(|&r| r as u64).product();
        state_bytes(slots, rows as u64, 1 + SH_DIM as u64)
    }
    /// Call `f` with the grid and the running averages (σ, SH): borrowed where the backend holds
    /// them in host memory (checkpoints of large grids copy nothing), else downloaded.
    fn with_state(&self, f: &mut StateFn) -> Result<()> {
        let (sd, ss) = self.optimizer_state()?;
        f(&self.grid()?, [&sd, &ss])
    }
    /// Replace grid and optimiser state (after resampling, or when resuming); the background
    /// stays.
    fn load(&mut self, grid: Grid, state: Option<(Vec<f32>, Vec<f32>)>) -> Result<()>;
    /// The background with its optimiser state (white and fixed unless set).
    fn background(&self) -> Result<Background>;
    /// Replace the background (colour, whether it is learned, its optimiser state).
    fn set_background(&mut self, bg: Background) -> Result<()>;
}

/// Ray → grid mapping of a grid: grid = p·scale + offset.
/// Stage 1's kernel and twin take no importance weights, so its batches must be drawn
/// uniformly: an error for views with a focus (`data::TrainViews::focused`).
pub fn uniform_views(views: &TrainViews) -> Result<()> {
    anyhow::ensure!(
        views.set().focus.is_none(),
        "stage 1 draws its batches uniformly (focused views were given)"
    );
    Ok(())
}

pub fn march_params(g: &Grid, stop_thresh: f32) -> MarchParams {
    MarchParams {
        scale: std::array::from_fn(|i| g.res[i] as f32 / (2.0 * g.radius[i])),
        offset: std::array::from_fn(|i| {
            (0.5 - g.center[i] / (2.0 * g.radius[i])) * g.res[i] as f32 - 0.5
        }),
        stop_thresh,
    }
}
