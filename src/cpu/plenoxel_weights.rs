//! Twin of `glsl/plenoxel_weights.comp`.

use crate::math::atomic;
use crate::math::plenoxel::{
    march_init, march_next, ray, sample_alpha, GridRef, MarchParams, PlenoxelCounts,
};
use rayon::prelude::*;

/// Twin of `plenoxel_weights.comp`: per allocated vertex, the max over samples of w·w_trilinear.
pub fn max_weights(g: &GridRef, rays: &[f32], mp: &MarchParams) -> Vec<f32> {
    let mut out = vec![0f32; g.density.len()];
    let mw = atomic::as_atomic(&mut out);
    (0..rays.len() / 6).into_par_iter().for_each(|r| {
        let (ro, rd) = ray(rays, r);
        let Some(m) = march_init(ro, rd, mp.scale, mp.offset, g.res) else {
            return;
        };
        let mut t_acc = 1.0f32;
        let mut k = 0;
        let mut counts = PlenoxelCounts::default();
        while let Some(s) = march_next(g, &m, &mut k, &mut counts) {
            let alpha = sample_alpha(s.sigma, m.delta);
            let wt = t_acc * alpha;
            for i in 0..8 {
                if s.lk[i] >= 0 {
                    atomic::max_nonneg(&mw[s.lk[i] as usize], wt * s.w[i]);
                }
            }
            t_acc *= 1.0 - alpha;
            if t_acc < mp.stop_thresh {
                break;
            }
        }
    });
    out
}
