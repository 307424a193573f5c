//! Stage-1 (Plenoxels) compute backends: one interface, a Vulkan implementation running the GLSL
//! kernels (one submission per training step) and a CPU implementation running their twins.

mod cpu;
pub mod plan;
mod vulkan;

pub use cpu::CpuPlenoxels;
pub use vulkan::VulkanPlenoxels;

use crate::abi::buffers::PlenoxelPerRay;
use crate::checkpoint::{self, format};
use crate::data::TrainViews;
use crate::gpu::StepTiming;
use crate::grid::state_bytes;
use crate::grid::{Grid, SH_DIM};
use crate::math::plenoxel::MarchParams;
use crate::math::plenoxel::PlenoxelCounts;
use crate::stage::{psnr, Saved, Stage, StageBackend};
use anyhow::{bail, Result};
use std::path::Path;

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
pub struct PlenoxelsStepParams {
    pub lr_sigma: f32,
    pub lr_sh: f32,
    pub beta: f32,
    pub eps: f32,
    pub stop_thresh: f32,
    pub tv: Option<TvParams>,
    /// RMSProp rate of a learned background (`background_step`; unused when it is fixed).
    pub lr_bg: f32,
    /// Weight of the TV on a learned background's spheres (unused without them).
    pub tv_background: f32,
    /// λ of the Cauchy sparsity loss on every shaded sample of the training rays (0: none).
    pub sparsity: f32,
}

/// What a step reports back.
#[derive(Clone, Copy, Debug, Default)]
pub struct PlenoxelsStepStats {
    /// Mean squared error over the batch's rays and channels.
    pub mse: f64,
    /// Samples shaded, evaluated at σ ≤ ε, skipped by the occupancy volume; gradient atomic adds.
    pub counts: PlenoxelCounts,
    /// Device and host time of the step.
    pub timing: StepTiming,
}

/// Output of `Plenoxels::gradients`.
#[derive(Clone, Debug, Default)]
pub struct Gradients {
    pub ray_loss: Vec<f32>,
    pub density: Vec<f32>,
    pub sh: Vec<f32>,
    /// dL/dbg of a learned background (zero when it is fixed).
    pub background: [f32; 3],
    /// dL/d(texel values) of learned background spheres (empty without them).
    pub spheres: Vec<f32>,
    pub counts: PlenoxelCounts,
}

/// Stage 1: the Plenoxels density and SH grid.
pub struct PlenoxelsStage;

impl Stage for PlenoxelsStage {
    const NAME: &'static str = "plenoxels";
    const TRAINS_SPHERES: bool = true;
    const CHECKPOINT: &'static str = crate::run::dir::PLENOXELS_CHECKPOINT;
    const STATE_NAMES: &'static [&'static str] = &["rms_density", "rms_sh"];
    /// `step` = steps done, `psnr_batch` = PSNR of that step's batch MSE, `elapsed_s` = seconds
    /// since training started.
    const LOG_HEADER: &'static str = "step,mse,psnr_batch,elapsed_s";
    type Grid = Grid;
    type Params = PlenoxelsStepParams;
    type Stats = PlenoxelsStepStats;
    type PerRay = PlenoxelPerRay;
    type State = [Vec<f32>; 2];

    fn mse(stats: &PlenoxelsStepStats) -> f64 {
        stats.mse
    }

    fn timing(stats: &mut PlenoxelsStepStats) -> &mut StepTiming {
        &mut stats.timing
    }

    fn non_finite(stats: &PlenoxelsStepStats) -> Option<String> {
        (!stats.mse.is_finite()).then(|| stats.mse.to_string())
    }

    fn log_row(stats: &PlenoxelsStepStats, step: u32, elapsed: f64) -> String {
        let mse = stats.mse;
        format!("{step},{mse:e},{:.4},{elapsed:.3}", psnr(mse))
    }

    fn tally(totals: &mut PlenoxelPerRay, stats: &PlenoxelsStepStats) {
        totals.add(&stats.counts);
    }

    fn scaled(totals: &PlenoxelPerRay, f: f64) -> PlenoxelPerRay {
        totals.scaled(f)
    }

    /// Stage 1's kernel and twin take no importance weights, so its batches must be drawn
    /// uniformly: an error for views with a focus (`data::TrainViews::focused`).
    fn check_views(views: &TrainViews) -> Result<()> {
        anyhow::ensure!(
            views.set().focus.is_none(),
            "stage 1 draws its batches uniformly (focused views were given)"
        );
        Ok(())
    }

    fn save(
        path: &Path,
        grid: &Grid,
        optim: &[(&str, &[f32])],
        meta: &serde_json::Value,
    ) -> Result<()> {
        check_finite(grid)?;
        format::save(path, grid, optim, meta)
    }

    fn load(path: &Path) -> Result<Saved<Self>> {
        let ck = format::load(path)?;
        Ok(Saved {
            state: checkpoint::state_of::<Self>(&ck.optim, path)?,
            spheres: checkpoint::spheres_of::<Self>(&ck.optim, &ck.meta, path)?,
            grid: ck.grid,
            meta: ck.meta,
        })
    }
}

/// Refuse a grid with a NaN or infinite value; the error names the first offender.
fn check_finite(grid: &Grid) -> Result<()> {
    for (name, v) in [("density", &grid.density), ("sh", &grid.sh)] {
        if let Some(i) = v.iter().position(|x| !x.is_finite()) {
            bail!("non-finite {name} value {} at vertex row {i}", v[i]);
        }
    }
    Ok(())
}

/// Bytes of a copy of a grid of `res` vertices with `rows` allocated and its running averages
/// (what a checkpoint holds).
pub fn state_bytes_of((res, rows): ([u32; 3], usize)) -> u64 {
    let slots = res.iter().map(|&r| r as u64).product();
    state_bytes(slots, rows as u64, 1 + SH_DIM as u64)
}

/// The stage-1 backend: [`StageBackend`] and what only stage 1 does (its data-term gradients,
/// renders and pruning weights).
pub trait PlenoxelsBackend: StageBackend<PlenoxelsStage> {
    /// The data-term gradients of a batch without updating anything: per-ray squared error,
    /// dL/dσ, dL/dSH and, when it is learned, dL/dbg (L = mean squared error over rays and
    /// channels, plus `sparsity`·Σ log(1 + 2σ²) over the shaded samples), and the sample counts.
    fn gradients(
        &mut self,
        rays: &[f32],
        targets: &[f32],
        stop_thresh: f32,
        sparsity: f32,
    ) -> Result<Gradients>;
    /// Render rays (composited on the background): 3 floats per ray, and the sample counts.
    fn render(&mut self, rays: &[f32], stop_thresh: f32) -> Result<(Vec<f32>, PlenoxelCounts)>;
    /// Max over rays and samples of w·w_trilinear per allocated vertex (pruning weights).
    fn max_weights(&mut self, rays: &[f32], stop_thresh: f32) -> Result<Vec<f32>>;
    /// Vertices per axis and allocated vertices of the current grid (nothing copied).
    fn shape(&self) -> ([u32; 3], usize);
}

/// Ray → grid mapping of a grid: grid = p·scale + offset.
pub fn march_params(g: &Grid, stop_thresh: f32) -> MarchParams {
    MarchParams {
        scale: std::array::from_fn(|i| g.res[i] as f32 / (2.0 * g.radius[i])),
        offset: std::array::from_fn(|i| {
            (0.5 - g.center[i] / (2.0 * g.radius[i])) * g.res[i] as f32 - 0.5
        }),
        stop_thresh,
    }
}
