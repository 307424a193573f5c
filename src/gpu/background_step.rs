//! Recording of the `background_step` kernel (one RMSProp step of a learned background colour,
//! clamped to [0, 1]), shared by both Vulkan backends.

use super::{Batch, GpuBuffer};
use crate::kernels;
use anyhow::Result;

/// Records one optimiser step of the background held in `bg` (a `Background` buffer).
pub fn record_background_step(
    b: &mut Batch,
    bg: &GpuBuffer,
    lr: f32,
    beta: f32,
    eps: f32,
) -> Result<()> {
    b.dispatch_1d(
        &kernels::background_step::INFO,
        &kernels::background_step::Push {
            bg: bg.address(),
            lr,
            beta,
            eps,
            ..Default::default()
        },
        3,
    )
}
