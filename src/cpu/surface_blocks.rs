//! Twin of `glsl/surface_blocks.comp`: the level mask of every 8³-cell block of a stage-2 grid
//! (coarse empty-space skipping for the surface walk; `math::surface_blocks` has the
//! conventions), one rayon task per block.

use super::surface_fwd::SurfaceGridRef;
use crate::math::surface::SURF_MAX_LEVELS;
use crate::math::surface_blocks::{
    surf_block_box, surf_block_mask, surf_blocks_per_axis, SURF_BLOCK_BIG, SURF_BLOCK_SHIFT,
};
use anyhow::{ensure, Result};
use rayon::prelude::*;

/// Block masks of grid `g` for `levels` (at most 8) widened by `margin` ≥ 0: `nb`³ entries,
/// `nb = ceil((n−1)/8)`, x-major; bit i set iff τ_i ∈ [bmin − margin, bmax + margin] over the
/// block's allocated vertices (0 if none). Pass `margin = 0` for masks of the current δ.
pub fn build_blocks(g: &SurfaceGridRef, levels: &[f32], margin: f32) -> Result<Vec<u32>> {
    g.validate()?;
    ensure!(
        levels.len() <= SURF_MAX_LEVELS,
        "at most {SURF_MAX_LEVELS} levels, got {}",
        levels.len()
    );
    ensure!(
        margin >= 0.0 && margin.is_finite(),
        "block margin must be finite and ≥ 0, got {margin}"
    );
    let n = g.n;
    let nb = surf_blocks_per_axis(n);
    Ok((0..nb * nb * nb)
        .into_par_iter()
        .map(|b| {
            let l = [b / (nb * nb), (b / nb) % nb, b % nb].map(|x| (x as i32) << SURF_BLOCK_SHIFT);
            let (lo, hi) = surf_block_box(l, n as i32);
            let (v0, v1) = (lo.map(|x| x as u32), hi.map(|x| x as u32));
            let (mut bmin, mut bmax) = (SURF_BLOCK_BIG, -SURF_BLOCK_BIG);
            for x in v0[0]..=v1[0] {
                for y in v0[1]..=v1[1] {
                    let row = ((x * n + y) * n) as usize;
                    for z in v0[2]..=v1[2] {
                        let k = g.links[row + z as usize];
                        if k < 0 {
                            continue;
                        }
                        let d = g.delta[k as usize];
                        bmin = bmin.min(d);
                        bmax = bmax.max(d);
                    }
                }
            }
            surf_block_mask(bmin, bmax, margin, levels)
        })
        .collect())
}
