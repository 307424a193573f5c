//! Twin of `glsl/surface_live_cells.comp`: the live-cell words that open the stage-2 skip
//! structure (`cpu::surface_blocks::build_blocks`).

use crate::math::surface_blocks::{surf_block_mask, SURF_BLOCK_BIG};
use rayon::prelude::*;

/// The (min, max) of δ over `rows`; (SURF_BLOCK_BIG, −SURF_BLOCK_BIG) for none.
pub fn delta_range(delta: &[f32], rows: &[u32]) -> (f32, f32) {
    rows.iter()
        .fold((SURF_BLOCK_BIG, -SURF_BLOCK_BIG), |(lo, hi), &r| {
            let d = delta[r as usize];
            (lo.min(d), hi.max(d))
        })
}

/// Bit b of word w set when the cell with lower-corner slot 32w + b of the `n`³ grid is complete
/// (its bit in `complete`, `math::surface_blocks::complete_cells`) and a level τ lies in
/// [cmin − margin, cmax + margin] of its corners' δ: only the complete cells can be live.
pub fn surface_live_cells(
    complete: &[u32],
    links: &[i32],
    delta: &[f32],
    n: u32,
    levels: &[f32],
    margin: f32,
) -> Vec<u32> {
    let nn = n as usize;
    complete
        .par_iter()
        .enumerate()
        .map(|(w, &bits)| {
            if bits == 0 {
                return 0;
            }
            let mut live = 0u32;
            for b in (0..32).filter(|b| bits >> b & 1 != 0) {
                let ci = 32 * w + b;
                let corners: [u32; 8] = std::array::from_fn(|k| {
                    links[ci + (k >> 2) * nn * nn + ((k >> 1) & 1) * nn + (k & 1)] as u32
                });
                let (cmin, cmax) = delta_range(delta, &corners);
                if surf_block_mask(cmin, cmax, margin, levels) != 0 {
                    live |= 1 << b;
                }
            }
            live
        })
        .collect()
}
