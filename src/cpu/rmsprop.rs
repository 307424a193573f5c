//! Twins of `glsl/lib/rmsprop.glsl` (one scalar), `glsl/rmsprop_sparse.comp` (σ and 27 SH of
//! every touched vertex, then the flag cleared) and `glsl/surface_rmsprop.comp` (the same for the
//! stage-2 groups δ, σα and SH, each only where it was touched, and δ and σα on ranges of rows).

use super::step::{RowRange, TOUCH_DELTA, TOUCH_OPACITY, TOUCH_SH};
use crate::grid::SH_DIM;
use rayon::prelude::*;

/// Hyper-parameters of one RMSProp step.
#[derive(Clone, Copy, Debug)]
pub struct RmsProp {
    pub lr_sigma: f32,
    pub lr_sh: f32,
    pub beta: f32,
    pub eps: f32,
}

/// r ← (r == 0 ? g² : βr + (1 − β)g²); θ ← θ − lr·g/(√r + ε); g ← 0.
pub fn rmsprop_one(p: &mut f32, g: &mut f32, r: &mut f32, lr: f32, beta: f32, eps: f32) {
    let g2 = *g * *g;
    let rn = if *r == 0.0 {
        g2
    } else {
        beta * *r + (1.0 - beta) * g2
    };
    *r = rn;
    *p -= lr * *g / (rn.sqrt() + eps);
    *g = 0.0;
}

/// Parameters, gradients and RMS state of the stage-1 grid.
pub struct Stage1Params<'a> {
    pub density: &'a mut [f32],
    pub sh: &'a mut [f32],
    pub grad_density: &'a mut [f32],
    pub grad_sh: &'a mut [f32],
    pub state_density: &'a mut [f32],
    pub state_sh: &'a mut [f32],
}

/// Update every vertex whose flag is set, and clear the flags.
pub fn rmsprop_sparse(p: Stage1Params, touched: &mut [u32], h: &RmsProp) {
    p.density
        .par_iter_mut()
        .zip(p.grad_density.par_iter_mut())
        .zip(p.state_density.par_iter_mut())
        .zip(p.sh.par_chunks_mut(SH_DIM))
        .zip(p.grad_sh.par_chunks_mut(SH_DIM))
        .zip(p.state_sh.par_chunks_mut(SH_DIM))
        .zip(touched.par_iter_mut())
        .for_each(|((((((d, gd), sd), sh), gs), ss), t)| {
            if *t == 0 {
                return;
            }
            rmsprop_one(d, gd, sd, h.lr_sigma, h.beta, h.eps);
            for k in 0..SH_DIM {
                rmsprop_one(&mut sh[k], &mut gs[k], &mut ss[k], h.lr_sh, h.beta, h.eps);
            }
            *t = 0;
        });
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

/// Parameters, gradients and RMS state of the stage-2 grid (per allocated vertex: δ, raw
/// opacity σα, 27 SH).
pub struct Stage2Params<'a> {
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

impl<'a> Stage2Params<'a> {
    /// The nine arrays in field order: δ, σα, SH, their gradients, their RMS states.
    pub fn from_arrays(p: &'a mut [Vec<f32>; 9]) -> Self {
        let [d, o, sh, gd, go, gs, sd, so, ss] = p;
        Stage2Params {
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
pub fn surface_rmsprop_sparse(p: Stage2Params, touched: &mut [u32], h: &SurfaceRmsProp) {
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
