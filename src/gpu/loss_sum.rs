//! Recording of the `loss_sum` kernel (a batch's per-ray loss fields summed on the device; CPU
//! twin `cpu::loss_sum`).

use super::Batch;
use crate::kernels;
use anyhow::Result;

/// Record summing the first `fields` floats of the `n` records of `stride` floats at `src` into
/// `fields` floats at `dst`.
pub fn record_loss_sum(
    b: &mut Batch,
    src: u64,
    dst: u64,
    n: usize,
    stride: u32,
    fields: u32,
) -> Result<()> {
    b.dispatch(
        &kernels::loss_sum::INFO,
        &kernels::loss_sum::Push {
            src,
            dst,
            n: n as u32,
            stride,
            fields,
            ..Default::default()
        },
        [1, 1, 1],
    )
}
