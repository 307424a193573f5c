//! Twin of `glsl/rmsprop_sparse.comp`: σ and 27 SH of every touched vertex, then the flag
//! cleared.

use crate::abi::train::RmsProp;
use crate::grid::SH_DIM;
use crate::math::rmsprop::rmsprop_one;
use rayon::prelude::*;

/// Parameters, gradients and RMS state of the stage-1 grid.
pub struct PlenoxelsOptimArrays<'a> {
    pub density: &'a mut [f32],
    pub sh: &'a mut [f32],
    pub grad_density: &'a mut [f32],
    pub grad_sh: &'a mut [f32],
    pub state_density: &'a mut [f32],
    pub state_sh: &'a mut [f32],
}

/// Update every vertex whose flag is set, and clear the flags.
pub fn rmsprop_sparse(p: PlenoxelsOptimArrays, touched: &mut [u32], h: &RmsProp) {
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
