//! Recording of the `optim_args` kernel (the touched count of a step record → the indirect
//! dispatch arguments of a sparse optimiser pass), shared by both Vulkan backends and their checks.

use super::{Batch, GpuBuffer};
use crate::kernels;
use anyhow::Result;

/// Records `optim_args` on the step record `step`, writing the three dispatch arguments to `args`.
pub fn record_optim_args(b: &mut Batch, step: &GpuBuffer, args: &GpuBuffer) -> Result<()> {
    b.dispatch(
        &kernels::optim_args::INFO,
        &kernels::optim_args::Push {
            step: step.address(),
            args: args.address(),
        },
        [1, 1, 1],
    )
}
