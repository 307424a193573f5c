//! What one training step is given besides the grids: the optimisers' hyper-parameters (both
//! stages) and stage 2's per-ray loss weights.

use crate::abi::step::RowRange;

/// The background spheres' RMSProp rates against the grid's (svox2's `tnt` rates: σ 3 = 0.1 ×
/// 30, colour 0.1 = 10 × 0.01), following the grid's schedules.
pub const SPHERE_LR_SIGMA_SCALE: f32 = 0.1;
pub const SPHERE_LR_COLOUR_SCALE: f32 = 10.0;

/// Hyper-parameters of one RMSProp step of a learned background (`background_step`).
#[derive(Clone, Copy, Debug)]
pub struct BackgroundStep {
    /// The colour's rate.
    pub lr: f32,
    /// The grid's σ rate at the step (the spheres' σ steps at a multiple of it).
    pub lr_sigma: f32,
    /// Weight λ of the spheres' TV, added to their gradient before their step
    /// (`BackgroundSpheres::tv_chunk`; 0: none).
    pub sphere_tv: f32,
    pub beta: f32,
    pub eps: f32,
}

impl BackgroundStep {
    /// The step of a background when it is learned (`None` when it is fixed).
    pub fn when_learned(
        learned: bool,
        lr: f32,
        lr_sigma: f32,
        sphere_tv: f32,
        beta: f32,
        eps: f32,
    ) -> Option<Self> {
        learned.then_some(BackgroundStep {
            lr,
            lr_sigma,
            sphere_tv,
            beta,
            eps,
        })
    }

    /// The rates of the spheres' σ and colour ([`SPHERE_LR_SIGMA_SCALE`],
    /// [`SPHERE_LR_COLOUR_SCALE`]).
    pub fn sphere_rates(&self) -> [f32; 2] {
        [
            self.lr_sigma * SPHERE_LR_SIGMA_SCALE,
            self.lr * SPHERE_LR_COLOUR_SCALE,
        ]
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
