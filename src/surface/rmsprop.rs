//! Recording of `surface_rmsprop` on the Vulkan device (twin `cpu::surface_rmsprop`): the
//! range passes over the rows whose δ or σα is updated flagged or not, then the list pass over
//! the touched vertices; shared by `VulkanSurface` and the parity checks.

use crate::abi::train::SurfaceRmsProp;
use crate::gpu::{record_optim_args, Batch, GpuBuffer};
use crate::kernels;
use anyhow::Result;

use crate::abi::consts::RMSPROP_RANGE_ROWS;

/// The aligned row pairs (2m, 2m + 1) surface_rmsprop's range pass visits for the `len` rows from
/// `start` of a grid with `rows` rows (the kernel's count).
fn range_pairs(start: u32, len: u32, rows: u32) -> u32 {
    ((start & 1) + len).div_ceil(2).min(rows.div_ceil(2))
}

/// Device addresses of the parameter groups δ, σα, SH: values, gradients, RMS states.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceOptimIo {
    pub params: [u64; 3],
    pub grads: [u64; 3],
    pub states: [u64; 3],
}

/// Record one RMSProp step: the range passes (of `h.delta_rows` and `h.opacity_rows`, when they
/// hold rows), optim_args on `step`'s touched count into `args`, and the indirect list pass.
pub fn record_surface_rmsprop(
    b: &mut Batch,
    io: &SurfaceOptimIo,
    step: &GpuBuffer,
    args: &GpuBuffer,
    h: &SurfaceRmsProp,
) -> Result<()> {
    let (d, o) = (h.delta_rows, h.opacity_rows);
    let push = kernels::surface_rmsprop::Push {
        delta: io.params[0],
        opacity: io.params[1],
        sh: io.params[2],
        grad_delta: io.grads[0],
        grad_opacity: io.grads[1],
        grad_sh: io.grads[2],
        state_delta: io.states[0],
        state_opacity: io.states[1],
        state_sh: io.states[2],
        step: step.address(),
        lr_delta: h.lr_delta,
        lr_opacity: h.lr_opacity,
        lr_sh: h.lr_sh,
        beta: h.beta,
        eps: h.eps,
        rows: d.rows.max(o.rows),
        delta_start: d.start,
        delta_len: d.len,
        opacity_start: o.start,
        opacity_len: o.len,
        range_pass: 0,
        ..Default::default()
    };
    for (pass, start, len) in [(1, d.start, d.len), (2, o.start, o.len)] {
        if len > 0 {
            b.dispatch_1d(
                &kernels::surface_rmsprop::INFO,
                &kernels::surface_rmsprop::Push {
                    range_pass: pass,
                    ..push
                },
                range_pairs(start, len, push.rows).div_ceil(RMSPROP_RANGE_ROWS),
            )?;
        }
    }
    record_optim_args(b, step, args)?;
    b.dispatch_indirect(&kernels::surface_rmsprop::INFO, &push, args)
}
