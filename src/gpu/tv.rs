//! Recording of the `tv` kernel (TV of one field over a chunk of vertex slots), shared by both
//! Vulkan backends.

use super::{Batch, GpuBuffer};
use crate::abi::regularisers::TvChunk;
use crate::kernels;
use anyhow::Result;

/// Records TV on the field `data` (gradient into `grad`, touched flags into the step record
/// `step`) over `c`'s slots: the dispatch covers the chunk and the slots whose forward
/// neighbours lie in it.
pub fn record_tv(
    b: &mut Batch,
    links: &GpuBuffer,
    data: &GpuBuffer,
    grad: &GpuBuffer,
    step: &GpuBuffer,
    c: &TvChunk,
) -> Result<()> {
    b.dispatch_1d(
        &kernels::tv::INFO,
        &kernels::tv::Push {
            links: links.address(),
            data: data.address(),
            grad: grad.address(),
            step: step.address(),
            res: c.res,
            start: c.start,
            count: c.count,
            channels: c.channels,
            scale: c.scale,
            touch_bits: c.touch,
        },
        c.count + c.res[1] * c.res[2],
    )
}
