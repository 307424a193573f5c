//! Twins of `glsl/surface_live_cells.comp`, `glsl/surface_blocks.comp` and
//! `glsl/surface_block_radius.comp`: the skip structure of the stage-2 walks (`math::surface_blocks`
//! has the conventions) — a live bit per cell (all 8 corners allocated and some level within its
//! corners' δ range ± margin), then the level mask of every 2^shift-cell block (one rayon task per
//! bit word and per block) with the empty radius of the blocks without levels
//! (`math::surface_blocks::surf_block_radii`, the kernel's three passes).

use crate::abi::surface_grid::SurfaceGridRef;
use crate::math::surface::SURF_MAX_LEVELS;
use crate::math::surface_blocks::{
    surf_block_box, surf_block_mask, surf_block_radii, surf_blocks_per_axis, surf_live_words,
    SURF_BLOCK_BIG, SURF_BOX_WORDS,
};
use anyhow::{ensure, Result};
use rayon::prelude::*;

/// The skip structure of grid `g` for `levels` (at most 8), ranges widened by `margin` ≥ 0:
/// `surf_live_words(n)` words of live-cell bits (bit i of word i/32: the cell with lower-corner
/// slot i has its 8 corners allocated and a level τ in [cmin − margin, cmax + margin] of their δ),
/// then the `nb`³ block masks of 2^shift-cell blocks, `nb = ceil((n−1)/2^shift)`, x-major: bit i
/// set iff τ_i ∈ [bmin − margin, bmax + margin] over the block's allocated vertices (0 if none),
/// with the empty radius of a mask-0 block above (`surf_block_radii`), then the allocated box
/// ([`alloc_box`]). Pass `margin = 0` for the structure of the current δ.
pub fn build_blocks(
    g: &SurfaceGridRef,
    levels: &[f32],
    margin: f32,
    shift: u32,
) -> Result<Vec<u32>> {
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
    ensure!(
        (1..=8).contains(&shift),
        "block shift {shift}: want 2 to 256 cells per block edge"
    );
    let nb = surf_blocks_per_axis(n, shift);
    let mut out = live_cells(g, levels, margin);
    let words = out.len();
    out.extend(
        (0..nb * nb * nb)
            .into_par_iter()
            .map(|b| {
                let l = [b / (nb * nb), (b / nb) % nb, b % nb].map(|x| (x as i32) << shift);
                let (lo, hi) = surf_block_box(l, n as i32, shift, 0);
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
            .collect::<Vec<u32>>(),
    );
    surf_block_radii(&mut out[words..], nb);
    out.extend(alloc_box(g.links, n));
    Ok(out)
}

/// The box of the allocated vertices (`math::surface_blocks::SURF_BOX_WORDS`): lo x, y, z, hi x,
/// y, z in vertex coordinates of the `n`³ grid; [1, 1, 1, 0, 0, 0] when nothing is allocated.
/// Depends on the allocation only.
pub fn alloc_box(links: &[i32], n: u32) -> [u32; SURF_BOX_WORDS] {
    let n = n as usize;
    let (lo, hi) = links
        .par_iter()
        .enumerate()
        .filter(|(_, &l)| l >= 0)
        .map(|(s, _)| {
            let v = [s / (n * n), (s / n) % n, s % n].map(|x| x as u32);
            (v, v)
        })
        .reduce(
            || ([u32::MAX; 3], [0; 3]),
            |(a0, a1), (b0, b1)| {
                (
                    std::array::from_fn(|i| a0[i].min(b0[i])),
                    std::array::from_fn(|i| a1[i].max(b1[i])),
                )
            },
        );
    if lo[0] == u32::MAX {
        return [1, 1, 1, 0, 0, 0];
    }
    [lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]]
}

/// The live-cell words of [`build_blocks`] (as `surface_live_cells.comp`, which reads the cells'
/// allocation from precomputed complete-cell bits instead of the links: the same bits).
fn live_cells(g: &SurfaceGridRef, levels: &[f32], margin: f32) -> Vec<u32> {
    let n = g.n as usize;
    let cells = n * n * n;
    (0..surf_live_words(g.n) as usize)
        .into_par_iter()
        .map(|w| {
            let mut bits = 0u32;
            for b in 0..32 {
                let ci = 32 * w + b;
                if ci >= cells {
                    break;
                }
                let (x, y, z) = (ci / (n * n), (ci / n) % n, ci % n);
                if x + 1 >= n || y + 1 >= n || z + 1 >= n {
                    continue;
                }
                let (mut cmin, mut cmax) = (SURF_BLOCK_BIG, -SURF_BLOCK_BIG);
                let mut complete = true;
                for k in 0..8 {
                    let s = ci + (k >> 2) * n * n + ((k >> 1) & 1) * n + (k & 1);
                    let l = g.links[s];
                    if l < 0 {
                        complete = false;
                        break;
                    }
                    let d = g.delta[l as usize];
                    cmin = cmin.min(d);
                    cmax = cmax.max(d);
                }
                if complete && surf_block_mask(cmin, cmax, margin, levels) != 0 {
                    bits |= 1 << b;
                }
            }
            bits
        })
        .collect()
}

/// Bit i of word i/32 set when the cell whose lower corner is slot i (x-major, `n`³ slots) has
/// its 8 corners allocated: `surface_live_cells` reads these instead of the links.
pub fn complete_cells(links: &[i32], n: u32) -> Vec<u32> {
    let mut bits = vec![0u32; surf_live_words(n) as usize];
    let n = n as usize;
    let (nz, nyz) = (n, n * n);
    for x in 0..n.saturating_sub(1) {
        for y in 0..n - 1 {
            for z in 0..n - 1 {
                let s = (x * n + y) * n + z;
                let corners = [
                    s,
                    s + 1,
                    s + nz,
                    s + nz + 1,
                    s + nyz,
                    s + nyz + 1,
                    s + nyz + nz,
                    s + nyz + nz + 1,
                ];
                if corners.iter().all(|&c| links[c] >= 0) {
                    bits[s / 32] |= 1 << (s % 32);
                }
            }
        }
    }
    bits
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::surface_blocks::SURF_BLOCK_SHIFT_CPU;

    /// A 3³-vertex grid (8 cells), every vertex allocated with δ = its slot index.
    fn ramp() -> (Vec<i32>, Vec<f32>) {
        ((0..27).collect(), (0..27).map(|s| s as f32).collect())
    }

    fn live(links: &[i32], delta: &[f32], levels: &[f32], margin: f32) -> u32 {
        let (o, sh) = (vec![0.0; delta.len()], vec![0.0; delta.len() * 27]);
        let g = SurfaceGridRef {
            n: 3,
            links,
            delta,
            opacity: &o,
            sh: &sh,
            links_checked: false,
        };
        build_blocks(&g, levels, margin, SURF_BLOCK_SHIFT_CPU).unwrap()[0]
    }

    #[test]
    fn live_bits_are_inclusive_need_every_corner_and_honour_the_margin() {
        let (mut links, delta) = ramp();
        let c0 = 1u32;
        // τ = 13, the shared centre vertex's value, ends or lies in every cell's range
        // [s, s + 13] (s = lower-corner slot): all 8 cells live (closed ranges).
        let all = [0, 1, 3, 4, 9, 10, 12, 13]
            .iter()
            .fold(0u32, |m, &s| m | 1 << s);
        assert_eq!(live(&links, &delta, &[13.0], 0.0), all);
        // τ just above a cell's max: dead; the cell (1,1,1) range [13, 26] ends at 26.
        assert_eq!(live(&links, &delta, &[26.0], 0.0), 1 << 13);
        assert_eq!(live(&links, &delta, &[26.5], 0.0), 0);
        // Only the cells whose range holds τ = 0.5: cell (0,0,0) alone.
        assert_eq!(live(&links, &delta, &[0.5], 0.0), c0);
        // Just below every range: dead, until the margin reaches it.
        assert_eq!(live(&links, &delta, &[-0.25], 0.0), 0);
        assert_eq!(live(&links, &delta, &[-0.25], 0.25), c0);
        // An unallocated corner kills the cell whatever its range.
        links[13] = -1;
        assert_eq!(live(&links, &delta, &[0.5], 0.0), 0);
    }
}
