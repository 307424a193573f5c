//! Twin of `glsl/surface_blocks.comp`, and the whole skip structure of the stage-2 walks
//! (`math::surface_blocks` has the conventions) — a live bit per cell (all 8 corners allocated
//! and some level within its corners' δ range ± margin; twin `cpu::surface_live_cells`), then the
//! level mask of every 2^shift-cell block (one rayon task per block) with the empty radius of the
//! blocks without levels (twin `cpu::surf_block_radii`, the kernel's three passes).

use super::surface_live_cells::{delta_range, surface_live_cells};
use crate::abi::surface_grid::SurfaceGridRef;
use crate::math::surface::SURF_MAX_LEVELS;
use crate::math::surface_blocks::{
    alloc_box, complete_cells, surf_block_box, surf_block_mask, surf_block_radii,
    surf_blocks_per_axis, SURF_BOX_WORDS,
};
use anyhow::{ensure, Result};
use rayon::prelude::*;

/// The skip structure of grid `g` for `levels` (at most 8), ranges widened by `margin` ≥ 0:
/// `surf_live_words(n)` words of live-cell bits (bit i of word i/32: the cell with lower-corner
/// slot i has its 8 corners allocated and a level τ in [cmin − margin, cmax + margin] of their δ),
/// then the `nb`³ block masks of 2^shift-cell blocks, `nb = ceil((n−1)/2^shift)`, x-major: bit i
/// set iff τ_i ∈ [bmin − margin, bmax + margin] over the block's allocated vertices (0 if none),
/// with the empty radius of a mask-0 block above (`surf_block_radii`), then the allocated box
/// ([`alloc_box`]). Pass `margin = 0` for the structure of the current δ. A training loop that
/// rebuilds it keeps a [`SkipAllocation`] instead: this is one built and used once.
pub fn build_blocks(
    g: &SurfaceGridRef,
    levels: &[f32],
    margin: f32,
    shift: u32,
) -> Result<Vec<u32>> {
    g.validate()?;
    SkipAllocation::new(g.links, g.n, shift)?.build(g.links, g.delta, levels, margin)
}

/// What the skip structure ([`build_blocks`]) takes from the allocation alone, which training
/// never changes: the complete-cell bits ([`complete_cells`], as the kernels read them), the
/// allocated rows of each block's vertex box, and the allocated box. A rebuild then reads the δ of
/// allocated vertices only, not the n³ links (at 256³ with 0.7 % of the slots allocated, most of
/// a rebuild's time was reading links).
pub struct SkipAllocation {
    n: u32,
    shift: u32,
    complete: Vec<u32>,
    /// Per block (x-major), the rows of the allocated vertices of its box: `rows[starts[b] ..
    /// starts[b + 1]]`.
    starts: Vec<u32>,
    rows: Vec<u32>,
    /// Rows a δ must have: one more than the largest row a link names.
    rows_needed: usize,
    alloc_box: [u32; SURF_BOX_WORDS],
}

impl SkipAllocation {
    /// The allocation's part of the skip structure of the `n`³ grid `links` (checked by the
    /// caller: every link is −1 or a row) for blocks of 2^`shift` cells.
    pub fn new(links: &[i32], n: u32, shift: u32) -> Result<SkipAllocation> {
        ensure!(
            (1..=8).contains(&shift),
            "block shift {shift}: want 2 to 256 cells per block edge"
        );
        ensure!(
            links.len() == (n as usize).pow(3),
            "{} links for a grid of {n}³ vertices",
            links.len()
        );
        let nb = surf_blocks_per_axis(n, shift);
        let per_block: Vec<Vec<u32>> = (0..nb * nb * nb)
            .into_par_iter()
            .map(|b| {
                let l = [b / (nb * nb), (b / nb) % nb, b % nb].map(|x| (x as i32) << shift);
                let (lo, hi) = surf_block_box(l, n as i32, shift, 0);
                let (v0, v1) = (lo.map(|x| x as u32), hi.map(|x| x as u32));
                let mut rows = Vec::new();
                for x in v0[0]..=v1[0] {
                    for y in v0[1]..=v1[1] {
                        let row = ((x * n + y) * n) as usize;
                        for z in v0[2]..=v1[2] {
                            let k = links[row + z as usize];
                            if k >= 0 {
                                rows.push(k as u32);
                            }
                        }
                    }
                }
                rows
            })
            .collect();
        let mut starts = Vec::with_capacity(per_block.len() + 1);
        starts.push(0u32);
        for r in &per_block {
            starts.push(starts.last().copied().unwrap_or(0) + r.len() as u32);
        }
        let complete = complete_cells(links, n);
        Ok(SkipAllocation {
            n,
            shift,
            complete,
            starts,
            rows: per_block.concat(),
            rows_needed: links
                .iter()
                .map(|&l| (l + 1).max(0) as usize)
                .max()
                .unwrap_or(0),
            alloc_box: alloc_box(links, n),
        })
    }

    /// The skip structure of [`build_blocks`] for the δ of this allocation's rows (`links`: the
    /// allocation this was made from).
    pub fn build(
        &self,
        links: &[i32],
        delta: &[f32],
        levels: &[f32],
        margin: f32,
    ) -> Result<Vec<u32>> {
        ensure!(
            levels.len() <= SURF_MAX_LEVELS,
            "at most {SURF_MAX_LEVELS} levels, got {}",
            levels.len()
        );
        ensure!(
            margin >= 0.0 && margin.is_finite(),
            "block margin must be finite and ≥ 0, got {margin}"
        );
        ensure!(
            links.len() == (self.n as usize).pow(3) && self.rows_needed <= delta.len(),
            "a grid of {} links and {} δ rows for a skip allocation of {}³ vertices",
            links.len(),
            delta.len(),
            self.n
        );
        let mut out = surface_live_cells(&self.complete, links, delta, self.n, levels, margin);
        let words = out.len();
        out.par_extend(self.starts.par_windows(2).map(|s| {
            let (bmin, bmax) = delta_range(delta, &self.rows[s[0] as usize..s[1] as usize]);
            surf_block_mask(bmin, bmax, margin, levels)
        }));
        surf_block_radii(&mut out[words..], surf_blocks_per_axis(self.n, self.shift));
        out.extend(self.alloc_box);
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::surface_blocks::{surf_live_words, SURF_BLOCK_SHIFT_CPU};

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

    /// The skip structure's words by their definitions, cell by cell and block by block over
    /// the links (radii and box as `build_blocks` adds them).
    fn by_definition(
        n: u32,
        links: &[i32],
        delta: &[f32],
        levels: &[f32],
        margin: f32,
    ) -> Vec<u32> {
        let nn = n as usize;
        let slot = |x: usize, y: usize, z: usize| (x * nn + y) * nn + z;
        let mut out = vec![0u32; surf_live_words(n) as usize];
        for x in 0..nn - 1 {
            for y in 0..nn - 1 {
                for z in 0..nn - 1 {
                    let ls: Vec<i32> = (0..8)
                        .map(|k| links[slot(x + (k >> 2), y + ((k >> 1) & 1), z + (k & 1))])
                        .collect();
                    if ls.iter().any(|&l| l < 0) {
                        continue;
                    }
                    let d: Vec<f32> = ls.iter().map(|&l| delta[l as usize]).collect();
                    let (lo, hi) = (
                        d.iter().copied().fold(f32::MAX, f32::min),
                        d.iter().copied().fold(f32::MIN, f32::max),
                    );
                    if levels.iter().any(|&t| lo - margin <= t && t <= hi + margin) {
                        let s = slot(x, y, z);
                        out[s / 32] |= 1 << (s % 32);
                    }
                }
            }
        }
        let shift = SURF_BLOCK_SHIFT_CPU;
        let nb = surf_blocks_per_axis(n, shift) as usize;
        let words = out.len();
        for b in 0..nb * nb * nb {
            let bl = [b / (nb * nb), (b / nb) % nb, b % nb];
            let lo = bl.map(|v| v << shift);
            let hi = bl.map(|v| ((v + 1) << shift).min(nn - 1));
            let mut d = Vec::new();
            for x in lo[0]..=hi[0] {
                for y in lo[1]..=hi[1] {
                    for z in lo[2]..=hi[2] {
                        if links[slot(x, y, z)] >= 0 {
                            d.push(delta[links[slot(x, y, z)] as usize]);
                        }
                    }
                }
            }
            let mut mask = 0u32;
            if !d.is_empty() {
                let (dl, dh) = (
                    d.iter().copied().fold(f32::MAX, f32::min),
                    d.iter().copied().fold(f32::MIN, f32::max),
                );
                for (i, &t) in levels.iter().enumerate() {
                    if dl - margin <= t && t <= dh + margin {
                        mask |= 1 << i;
                    }
                }
            }
            out.push(mask);
        }
        surf_block_radii(&mut out[words..], nb as u32);
        out.extend(alloc_box(links, n));
        out
    }

    #[test]
    fn a_kept_allocation_rebuilds_the_structure_its_definition_gives() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
        // 21 and 18 vertices: blocks of 8 cells that do and do not fill the grid; a third of the
        // slots unallocated, whole blocks of them in one corner.
        for n in [21u32, 18] {
            let nn = n as usize;
            let mut links = vec![-1i32; nn * nn * nn];
            let mut rows = 0;
            for (s, l) in links.iter_mut().enumerate() {
                let (x, y, z) = (s / (nn * nn), (s / nn) % nn, s % nn);
                if (x < 9 && y < 9 && z < 9) || rng.random::<f32>() < 0.3 {
                    continue;
                }
                *l = rows;
                rows += 1;
            }
            let levels = [-0.5f32, 0.0, 0.7];
            let skip = SkipAllocation::new(&links, n, SURF_BLOCK_SHIFT_CPU).unwrap();
            // δ changes between rebuilds, as training moves it; the allocation does not.
            for round in 0..3 {
                let delta: Vec<f32> = (0..rows).map(|_| rng.random_range(-2.0..2.0f32)).collect();
                for margin in [0.0, 0.05, 0.6] {
                    let want = by_definition(n, &links, &delta, &levels, margin);
                    let got = skip.build(&links, &delta, &levels, margin).unwrap();
                    assert_eq!(got, want, "n {n}, round {round}, margin {margin}");
                    assert!(want[..surf_live_words(n) as usize].iter().any(|&w| w != 0));
                }
            }
            // A δ with fewer rows than the links name is refused, not read past.
            assert!(skip.build(&links, &[0.0; 3], &levels, 0.0).is_err());
        }
    }
}
