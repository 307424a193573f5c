//! A stage-1 training step as an ordered list of typed passes, built and validated once from the
//! step's parameters and the grid; the CPU backend runs each pass's twin, the Vulkan backend
//! records its kernel, both top to bottom. The order: occupancy → fused forward/backward → TV on
//! σ and SH → sparse RMSProp → background step (when it is learned).

use super::PlenoxelsStepParams;
use crate::abi::consts::TOUCH_ALL;
use crate::abi::regularisers::TvChunk;
use crate::abi::train::{BackgroundStep, RmsProp};
use crate::grid::SH_DIM;
use crate::math::plenoxel::LossWeights;
use anyhow::{ensure, Result};

/// Which parameter group a TV pass regularises.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TvField {
    Density,
    Sh,
}

/// One pass of a stage-1 step, with everything it needs besides the backend's buffers.
#[derive(Clone, Copy, Debug)]
pub enum PlenoxelPass {
    /// Rebuild the occupancy volume from σ (`occupancy`).
    Occupancy,
    /// The fused forward/backward pass over the batch (`plenoxel_train`): gradients += data term
    /// with dL/dC = loss.grad_scale·(C − target), and the sparsity term when loss.sparsity > 0.
    Train { stop_thresh: f32, loss: LossWeights },
    /// TV on one parameter group over a chunk of vertex slots (`tv`).
    Tv { field: TvField, chunk: TvChunk },
    /// Sparse RMSProp over the touched vertices (`optim_args` → `rmsprop_sparse`).
    RmsProp(RmsProp),
    /// RMSProp on a learned background (`background_step`).
    Background(BackgroundStep),
}

/// The passes of one stage-1 step, in order.
#[derive(Clone, Debug)]
pub struct PlenoxelPlan {
    passes: Vec<PlenoxelPass>,
}

/// The loss weights of a training pass over `n_rays` rays with the sparsity weight `sparsity`;
/// `grad_scale` is dL/dC of the batch mean squared error over the rays and their 3 channels.
pub fn batch_loss(n_rays: usize, sparsity: f32) -> LossWeights {
    LossWeights {
        grad_scale: 2.0 / (3.0 * n_rays as f32),
        sparsity,
    }
}

impl PlenoxelPlan {
    /// A training step on `n_rays` rays with `p` on a grid of resolution `res` (`learned_bg`: the
    /// background is learned). Refuses a TV chunk past the grid's slots.
    pub fn step(
        p: &PlenoxelsStepParams,
        res: [u32; 3],
        n_rays: usize,
        learned_bg: bool,
    ) -> Result<Self> {
        let mut passes = Self::gradients(p.stop_thresh, p.sparsity, n_rays).passes;
        if let Some(t) = p.tv {
            let slots: u64 = res.iter().map(|&r| r as u64).product();
            ensure!(
                t.start as u64 + t.count as u64 <= slots,
                "TV chunk of {} slots from {} on a {res:?} grid of {slots} slots",
                t.count,
                t.start
            );
            for (field, channels, lambda) in [
                (TvField::Density, 1, t.lambda_sigma),
                (TvField::Sh, SH_DIM as u32, t.lambda_sh),
            ] {
                let chunk = TvChunk {
                    res,
                    start: t.start,
                    count: t.count,
                    channels,
                    scale: lambda / t.count.max(1) as f32,
                    touch: TOUCH_ALL,
                };
                passes.push(PlenoxelPass::Tv { field, chunk });
            }
        }
        passes.push(PlenoxelPass::RmsProp(RmsProp {
            lr_sigma: p.lr_sigma,
            lr_sh: p.lr_sh,
            beta: p.beta,
            eps: p.eps,
        }));
        let bg = BackgroundStep::when_learned(
            learned_bg,
            p.lr_bg,
            p.lr_sigma,
            p.tv_background,
            p.beta,
            p.eps,
        );
        passes.extend(bg.map(PlenoxelPass::Background));
        Ok(PlenoxelPlan { passes })
    }

    /// The data term alone (no regulariser but the per-sample sparsity `sparsity`, no update):
    /// occupancy, then the training pass.
    pub fn gradients(stop_thresh: f32, sparsity: f32, n_rays: usize) -> Self {
        PlenoxelPlan {
            passes: vec![
                PlenoxelPass::Occupancy,
                PlenoxelPass::Train {
                    stop_thresh,
                    loss: batch_loss(n_rays, sparsity),
                },
            ],
        }
    }

    /// The passes, in the order they run.
    pub fn passes(&self) -> &[PlenoxelPass] {
        &self.passes
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plenoxel::TvParams;

    fn params(tv: Option<TvParams>) -> PlenoxelsStepParams {
        PlenoxelsStepParams {
            lr_sigma: 30.0,
            lr_sh: 1e-2,
            beta: 0.95,
            eps: 1e-8,
            stop_thresh: 1e-4,
            tv,
            lr_bg: 1e-2,
            tv_background: 1e-3,
            sparsity: 1e-9,
        }
    }

    fn names(plan: &PlenoxelPlan) -> Vec<&'static str> {
        plan.passes()
            .iter()
            .map(|p| match p {
                PlenoxelPass::Occupancy => "occupancy",
                PlenoxelPass::Train { .. } => "train",
                PlenoxelPass::Tv {
                    field: TvField::Density,
                    ..
                } => "tv_density",
                PlenoxelPass::Tv {
                    field: TvField::Sh, ..
                } => "tv_sh",
                PlenoxelPass::RmsProp(_) => "rmsprop",
                PlenoxelPass::Background(_) => "background",
            })
            .collect()
    }

    #[test]
    fn passes_follow_the_step_order() {
        let tv = TvParams {
            start: 100,
            count: 412,
            lambda_sigma: 1e-5,
            lambda_sh: 1e-3,
        };
        let plan = PlenoxelPlan::step(&params(Some(tv)), [8, 8, 8], 64, true).unwrap();
        assert_eq!(
            names(&plan),
            [
                "occupancy",
                "train",
                "tv_density",
                "tv_sh",
                "rmsprop",
                "background"
            ]
        );
        for pass in plan.passes() {
            match pass {
                PlenoxelPass::Train { loss, .. } => assert_eq!(
                    *loss,
                    LossWeights {
                        grad_scale: 2.0 / 192.0,
                        sparsity: 1e-9
                    }
                ),
                PlenoxelPass::Tv { field, chunk } => {
                    let (channels, lambda) = match field {
                        TvField::Density => (1, 1e-5),
                        TvField::Sh => (SH_DIM as u32, 1e-3),
                    };
                    assert_eq!((chunk.start, chunk.count), (100, 412));
                    assert_eq!(chunk.channels, channels);
                    assert_eq!(chunk.scale, lambda / 412.0);
                    assert_eq!(chunk.touch, TOUCH_ALL);
                }
                PlenoxelPass::Background(s) => assert_eq!(s.sphere_tv, 1e-3),
                _ => {}
            }
        }
        let bare = PlenoxelPlan::step(&params(None), [8, 8, 8], 64, false).unwrap();
        assert_eq!(names(&bare), ["occupancy", "train", "rmsprop"]);
    }

    #[test]
    fn tv_chunk_past_the_grid_is_refused() {
        let tv = TvParams {
            start: 100,
            count: 413,
            lambda_sigma: 1e-5,
            lambda_sh: 1e-3,
        };
        let err = PlenoxelPlan::step(&params(Some(tv)), [8, 8, 8], 64, false).unwrap_err();
        assert!(
            err.to_string().contains("TV chunk of 413 slots from 100"),
            "{err}"
        );
    }
}
