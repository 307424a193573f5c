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

use crate::abi::buffers::SurfCounts;
use crate::abi::buffers::TrainCounts;
use crate::abi::buffers::TrainPerRay;
use crate::abi::regularisers::DeltaTvChunk;
use crate::abi::regularisers::OpacityChunk;
use crate::abi::regularisers::TvChunk;
use crate::abi::train::SurfaceLoss;
use crate::checkpoint;
use crate::gpu::StepTiming;
use crate::grid::surface::SurfaceGrid;
use crate::math::surface::SurfaceParams;
use crate::math::surface::Truncation;
use crate::stage::{psnr, Saved, Stage, StageBackend};
use anyhow::Result;
use std::path::Path;

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
    /// Device and host time of the step.
    pub timing: StepTiming,
}

/// Stage 2: the αSurf surface grid.
pub struct SurfaceStage;

impl Stage for SurfaceStage {
    const NAME: &'static str = "surface";
    const TRAINS_SPHERES: bool = false;
    const CHECKPOINT: &'static str = crate::run::dir::SURFACE_CHECKPOINT;
    const STATE_NAMES: &'static [&'static str] = &["rms_delta", "rms_opacity", "rms_sh"];
    /// Step, mse, batch PSNR, the unweighted entropy and consistency means, the regulariser
    /// loss (Lα + Ln), seconds since training started.
    const LOG_HEADER: &'static str = "step,mse,psnr_batch,entropy,consistency,reg_loss,elapsed_s";
    type Grid = SurfaceGrid;
    type Params = SurfaceStepParams;
    type Stats = SurfaceStepStats;
    type PerRay = TrainPerRay;
    /// δ, σα, SH.
    type State = [Vec<f32>; 3];

    fn mse(stats: &SurfaceStepStats) -> f64 {
        stats.mse
    }

    fn timing(stats: &mut SurfaceStepStats) -> &mut StepTiming {
        &mut stats.timing
    }

    fn non_finite(s: &SurfaceStepStats) -> Option<String> {
        (!(s.mse.is_finite() && s.entropy.is_finite() && s.consistency.is_finite())).then(|| {
            format!(
                "mse {}, entropy {}, consistency {}",
                s.mse, s.entropy, s.consistency
            )
        })
    }

    fn log_row(s: &SurfaceStepStats, step: u32, elapsed: f64) -> String {
        format!(
            "{},{:.6e},{:.3},{:.5},{:.5},{:.4e},{:.3}",
            step,
            s.mse,
            psnr(s.mse),
            s.entropy,
            s.consistency,
            s.reg_loss,
            elapsed
        )
    }

    fn tally(totals: &mut TrainPerRay, stats: &SurfaceStepStats) {
        totals.add(&stats.counts);
    }

    fn scaled(totals: &TrainPerRay, f: f64) -> TrainPerRay {
        totals.scaled(f)
    }

    fn save(
        path: &Path,
        grid: &SurfaceGrid,
        optim: &[(&str, &[f32])],
        meta: &serde_json::Value,
    ) -> Result<()> {
        checkpoint::surface::save(path, grid, optim, meta)
    }

    fn load(path: &Path) -> Result<Saved<Self>> {
        let ck = checkpoint::surface::load(path)?;
        Ok(Saved {
            state: checkpoint::state_of::<Self>(&ck.optim, path)?,
            spheres: checkpoint::spheres_of::<Self>(&ck.optim, &ck.meta, path)?,
            grid: ck.grid,
            meta: ck.meta,
        })
    }
}

/// The stage-2 backend: [`StageBackend`] and its renders.
pub trait SurfaceBackend: StageBackend<SurfaceStage> {
    /// Render rays (composited on the background): 3 floats per ray, and the counters of
    /// `surface_fwd`.
    fn render(
        &mut self,
        rays: &[f32],
        truncation: Truncation,
        stop_thresh: f32,
    ) -> Result<(Vec<f32>, SurfCounts)>;
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
        spheres: None,
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
