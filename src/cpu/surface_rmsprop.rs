//! Twin of `glsl/surface_rmsprop.comp`: the RMSProp step of the stage-2 groups δ, σα and SH,
//! each only where it was touched, and δ and σα on ranges of rows.

use crate::abi::consts::{TOUCH_DELTA, TOUCH_OPACITY, TOUCH_SH};
use crate::abi::train::SurfaceRmsProp;
use crate::grid::SH_DIM;
use crate::math::rmsprop::rmsprop_one;
use rayon::prelude::*;

/// Parameters, gradients and RMS state of the stage-2 grid (per allocated vertex: δ, raw
/// opacity σα, 27 SH).
pub struct SurfaceOptimArrays<'a> {
    pub delta: &'a mut [f32],
    pub opacity: &'a mut [f32],
    pub sh: &'a mut [f32],
    pub grad_delta: &'a mut [f32],
    pub grad_opacity: &'a mut [f32],
    pub grad_sh: &'a mut [f32],
    pub state_delta: &'a mut [f32],
    pub state_opacity: &'a mut [f32],
    pub state_sh: &'a mut [f32],
}

impl<'a> SurfaceOptimArrays<'a> {
    /// The nine arrays in field order: δ, σα, SH, their gradients, their RMS states.
    pub fn from_arrays(p: &'a mut [Vec<f32>; 9]) -> Self {
        let [d, o, sh, gd, go, gs, sd, so, ss] = p;
        SurfaceOptimArrays {
            delta: d,
            opacity: o,
            sh,
            grad_delta: gd,
            grad_opacity: go,
            grad_sh: gs,
            state_delta: sd,
            state_opacity: so,
            state_sh: ss,
        }
    }
}

/// Update, per vertex, each group whose touched bit (step.rs TOUCH_*) is set — δ also on every row
/// of `delta_rows`, σα on every row of `opacity_rows` — clearing the updated gradients, and clear
/// the flags (surface_rmsprop.comp's range and list passes in one).
pub fn surface_rmsprop(p: SurfaceOptimArrays, touched: &mut [u32], h: &SurfaceRmsProp) {
    let scalars = p
        .delta
        .par_iter_mut()
        .zip(p.grad_delta.par_iter_mut())
        .zip(p.state_delta.par_iter_mut())
        .zip(p.opacity.par_iter_mut())
        .zip(p.grad_opacity.par_iter_mut())
        .zip(p.state_opacity.par_iter_mut());
    scalars
        .zip(p.sh.par_chunks_mut(SH_DIM))
        .zip(p.grad_sh.par_chunks_mut(SH_DIM))
        .zip(p.state_sh.par_chunks_mut(SH_DIM))
        .zip(touched.par_iter_mut())
        .enumerate()
        .for_each(
            |(v, (((((((((d, gd), sd), o), go), so), sh), gs), ss), t))| {
                if h.delta_rows.contains(v) || *t & TOUCH_DELTA != 0 {
                    rmsprop_one(d, gd, sd, h.lr_delta, h.beta, h.eps);
                }
                if h.opacity_rows.contains(v) || *t & TOUCH_OPACITY != 0 {
                    rmsprop_one(o, go, so, h.lr_opacity, h.beta, h.eps);
                }
                if *t & TOUCH_SH != 0 {
                    for k in 0..SH_DIM {
                        rmsprop_one(&mut sh[k], &mut gs[k], &mut ss[k], h.lr_sh, h.beta, h.eps);
                    }
                }
                *t = 0;
            },
        );
}
