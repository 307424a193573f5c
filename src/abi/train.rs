//! What one training step is given besides the grids: the optimisers' hyper-parameters (both
//! stages) and stage 2's per-ray loss weights.

use crate::abi::step::RowRange;

/// Hyper-parameters of one RMSProp step of a learned background (`background_step`).
#[derive(Clone, Copy, Debug)]
pub struct BackgroundStep {
    pub lr: f32,
    pub beta: f32,
    pub eps: f32,
}

impl BackgroundStep {
    /// The step of a background when it is learned (`None` when it is fixed).
    pub fn when_learned(learned: bool, lr: f32, beta: f32, eps: f32) -> Option<Self> {
        learned.then_some(BackgroundStep { lr, beta, eps })
    }
}

/// Hyper-parameters of one RMSProp step.
#[derive(Clone, Copy, Debug)]
pub struct RmsProp {
    pub lr_sigma: f32,
    pub lr_sh: f32,
    pub beta: f32,
    pub eps: f32,
}

/// Hyper-parameters of one stage-2 RMSProp step (one learning rate per parameter group).
#[derive(Clone, Copy, Debug)]
pub struct SurfaceRmsProp {
    pub lr_delta: f32,
    pub lr_opacity: f32,
    pub lr_sh: f32,
    pub beta: f32,
    pub eps: f32,
    /// The rows whose δ is updated flagged or not (those the step's δ regularisers reach: Lδ's
    /// window, every row for a whole-grid Lδ); elsewhere δ only where its flag bit is set.
    pub delta_rows: RowRange,
    /// Likewise for σα: the rows of Lα's chunk.
    pub opacity_rows: RowRange,
}

/// Loss weights of the fused per-ray terms (per-ray coefficients: the batch mean is the caller's).
#[derive(Clone, Copy, Debug)]
pub struct SurfaceLoss {
    /// dL/dC = grad_scale·(C − target) (2/(3B) for the mean squared error).
    pub grad_scale: f32,
    /// Weight of the entropy of the ray's normalised hit weights.
    pub lambda_h: f32,
    /// Weight of Σ |t_j − t_mode|.
    pub lambda_c: f32,
}
