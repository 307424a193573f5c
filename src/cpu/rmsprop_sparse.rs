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

/// Rows per task of [`rmsprop_sparse`]: a step touches a small share of a large grid's rows, and
/// a block with no flag set is passed over after one scan of its flags.
const ROWS_PER_BLOCK: usize = 1024;

/// Update every vertex whose flag is set, and clear the flags.
pub fn rmsprop_sparse(p: PlenoxelsOptimArrays, touched: &mut [u32], h: &RmsProp) {
    const B: usize = ROWS_PER_BLOCK;
    p.density
        .par_chunks_mut(B)
        .zip(p.grad_density.par_chunks_mut(B))
        .zip(p.state_density.par_chunks_mut(B))
        .zip(p.sh.par_chunks_mut(SH_DIM * B))
        .zip(p.grad_sh.par_chunks_mut(SH_DIM * B))
        .zip(p.state_sh.par_chunks_mut(SH_DIM * B))
        .zip(touched.par_chunks_mut(B))
        .for_each(|((((((d, gd), sd), sh), gs), ss), t)| {
            if t.iter().all(|&f| f == 0) {
                return;
            }
            for (i, f) in t.iter_mut().enumerate() {
                if *f == 0 {
                    continue;
                }
                rmsprop_one(&mut d[i], &mut gd[i], &mut sd[i], h.lr_sigma, h.beta, h.eps);
                for k in SH_DIM * i..SH_DIM * (i + 1) {
                    rmsprop_one(&mut sh[k], &mut gs[k], &mut ss[k], h.lr_sh, h.beta, h.eps);
                }
                *f = 0;
            }
        });
}
