//! Coarse empty-space skipping for the stage-2 (αSurf) cell walk: the twin of
//! `glsl/lib/surface_blocks.glsl` (same operations in the same order; that file has the
//! conventions and the exactness argument).
//!
//! A block is B³ cells, B = 2^shift (the backend's choice: [`SURF_BLOCK_SHIFT_CPU`],
//! [`SURF_BLOCK_SHIFT_VULKAN`]): block b (per axis) covers cells [Bb, Bb+B) ∩ [0, n−2], i.e. the
//! vertex range [Bb, min(Bb+B, n−1)]; `nb = ceil((n−1)/B)` blocks per axis, x-major. A block's
//! level mask has bit i set iff τ_i ∈ [bmin − margin, bmax + margin] over its allocated vertices
//! (0 if none): a block with mask 0 holds no hit. Its word also holds its empty radius r
//! ([`surf_block_radii`]): the blocks within Chebyshev distance r of it have mask 0 too, and the
//! walk jumps to the exit of that cube of blocks with [`surf_block_skip`].
//!
//! Use in a walk loop (as in `math::surface_walk::CellWalk`):
//! ```text
//! let mut w = dda_init(og, dn, n, 0.0);
//! let mut skipped = SURF_NO_BLOCK;
//! while let Some(piece) = dda_next(&mut w) {
//!     let bi = surf_block_index(piece.cell, nb, shift);
//!     let word = blocks[bi as usize];
//!     if word & SURF_MASK_BITS == 0
//!         && surf_block_skip(&mut w, dn, n, piece.cell, bi, &mut skipped, shift,
//!                            word >> SURF_RADIUS_SHIFT)
//!     {
//!         continue; // w restarts at the exit of the empty cube around the block
//!     }
//!     // ... the cell as before ...
//! }
//! ```

use super::dda::{dda_flush, ray_box, Dda, DDA_BIG};
use rayon::prelude::*;

/// log2 of the block edge each backend skips with, the faster in `bench surface`
/// (docs/tuning.md): 8³ on the CPU twins (a restart costs a scalar walk more than the cells it
/// jumps), 4³ on lavapipe (a walk step costs its SIMD lanes more than a restart).
pub const SURF_BLOCK_SHIFT_CPU: u32 = 3;
pub const SURF_BLOCK_SHIFT_VULKAN: u32 = 2;
pub use crate::abi::consts::{
    SURF_BLOCK_BIG, SURF_BOX_WORDS, SURF_MASK_BITS, SURF_MAX_RADIUS, SURF_NO_BLOCK,
    SURF_RADIUS_SHIFT,
};

// The skip structure ends with SURF_BOX_WORDS words: the box of the allocated vertices, lo x, y,
// z then hi x, y, z (vertex coordinates; lo > hi when nothing is allocated). A cell the walk can
// solve has its 8 corners allocated, so it lies inside: a walk starts at the ray's entry into
// the box and ends at its exit ([`surf_box_span`]). Exact: the entry is a plane crossing computed
// with the DDA's own formula (`ray_box`), and `dda_init(og, dn, n, t)` is the continuous walk's
// state at such a t (as for a block exit).

/// The t span `[t_in, t_out]` of the ray (`og`, `dn` as given to `dda_init`) inside the allocated
/// box `b` ([`SURF_BOX_WORDS`] words): the walk starts with `dda_init(og, dn, n, t_in)` and ends at
/// the first piece entered at `t_out` or later; `t_in ≥ t_out` (or NaN) when it misses the box.
pub fn surf_box_span(og: [f32; 3], dn: [f32; 3], b: &[u32]) -> [f32; 2] {
    if (0..3).any(|a| b[a] > b[3 + a]) {
        return [DDA_BIG, -DDA_BIG];
    }
    let lo = [b[0] as f32, b[1] as f32, b[2] as f32];
    let hi = [b[3] as f32, b[4] as f32, b[5] as f32];
    ray_box(og, dn, lo, hi, 0.0)
}

/// A walk's skip structure (`cpu::surface_blocks::build_blocks`): the live-cell words, the nb³
/// block masks of 2^shift-cell blocks, then the allocated box ([`SURF_BOX_WORDS`]).
#[derive(Clone, Copy, Debug)]
pub struct SkipRef<'a> {
    pub words: &'a [u32],
    pub shift: u32,
}

/// Blocks per axis of an `n`³-vertex grid (n ≥ 2) with 2^shift-cell blocks: ceil((n − 1)/2^shift).
pub fn surf_blocks_per_axis(n: u32, shift: u32) -> u32 {
    (n + (1 << shift) - 2) >> shift
}

/// Words of live-cell bits of an `n`³-vertex grid: ⌈n³/32⌉ (at least 1). The walks' skip
/// structure is these words (bit i of word i/32: cell with lower-corner slot i is live), then
/// the nb³ block masks.
pub fn surf_live_words(n: u32) -> u32 {
    (n * n * n).div_ceil(32).max(1)
}

/// Linear index of the block holding cell `l`.
pub fn surf_block_index(l: [i32; 3], nb: u32, shift: u32) -> u32 {
    let b = l.map(|x| (x >> shift) as u32);
    (b[0] * nb + b[1]) * nb + b[2]
}

/// Vertex box `(lo, hi)` of the blocks within Chebyshev distance `r` of the block holding cell `l`
/// (the block itself for r = 0), clipped to the grid of `n`³ vertices.
pub fn surf_block_box(l: [i32; 3], n: i32, shift: u32, r: u32) -> ([f32; 3], [f32; 3]) {
    let b = l.map(|x| x >> shift);
    let r = r as i32;
    (
        b.map(|x| ((x - r).max(0) << shift) as f32),
        b.map(|x| ((x + r + 1) << shift).min(n - 1) as f32),
    )
}

/// One block's value in pass `pass` (0, 1, 2: along x, y, z) of the empty-radius computation
/// (twin of the kernel `surface_block_radius`), over the nb³ values `src`: pass 0 reads the block
/// words (a block with levels counts 0, one without [`SURF_MAX_RADIUS`] + 1), later passes the
/// previous pass's values; the value is min over |k| ≤ [`SURF_MAX_RADIUS`] (blocks inside the
/// grid) of max(|k|, value at b + k along the axis). After the three passes it is the Chebyshev
/// distance from b to the nearest block with levels, capped at [`SURF_MAX_RADIUS`] + 1 (min and
/// max compose separably for that distance).
pub fn surf_radius_value(src: &[u32], nb: u32, pass: u32, b: u32) -> u32 {
    let far = SURF_MAX_RADIUS + 1;
    let stride = [nb * nb, nb, 1][pass as usize];
    let pos = (b / stride) % nb;
    let value = |i: u32| {
        let v = src[i as usize];
        match pass {
            0 if v & SURF_MASK_BITS != 0 => 0,
            0 => far,
            _ => v,
        }
    };
    let mut best = far;
    // max(k, ·) ≥ k: nothing at k ≥ best can lower it.
    for k in 0..=SURF_MAX_RADIUS {
        if k >= best {
            break;
        }
        if pos >= k {
            best = best.min(k.max(value(b - k * stride)));
        }
        if pos + k < nb {
            best = best.min(k.max(value(b + k * stride)));
        }
    }
    best
}

/// Adds the empty radius to the nb³ block `words` (level masks): a block without levels at
/// Chebyshev distance d from the nearest block with levels gets r = min(d, [`SURF_MAX_RADIUS`] +
/// 1) − 1 in its bits from [`SURF_RADIUS_SHIFT`] on (the three passes of [`surf_radius_value`]).
pub fn surf_block_radii(words: &mut [u32], nb: u32) {
    let count = nb * nb * nb;
    let x: Vec<u32> = (0..count)
        .map(|b| surf_radius_value(words, nb, 0, b))
        .collect();
    let y: Vec<u32> = (0..count)
        .map(|b| surf_radius_value(&x, nb, 1, b))
        .collect();
    for b in 0..count {
        let d = surf_radius_value(&y, nb, 2, b);
        let w = &mut words[b as usize];
        if *w & SURF_MASK_BITS == 0 {
            *w |= (d - 1) << SURF_RADIUS_SHIFT;
        }
    }
}

/// Block level mask from the block's δ range: bit i set iff
/// `bmin − margin ≤ levels[i] ≤ bmax + margin` (at most 8 levels); 0 for an empty range.
pub fn surf_block_mask(bmin: f32, bmax: f32, margin: f32, levels: &[f32]) -> u32 {
    let lo = bmin - margin;
    let hi = bmax + margin;
    let has = bmin <= bmax;
    levels
        .iter()
        .take(8)
        .enumerate()
        .filter(|(_, &tau)| has && lo <= tau && tau <= hi)
        .fold(0, |m, (i, _)| m | 1 << i)
}

/// t at which walk `w` leaves the box of the blocks within `r` of the block holding cell `l`
/// ([`surf_block_box`]): min over moving axes of the box's far-plane crossing `(k − o)·(1/d)`
/// (o, 1/d as stored in `w`), bit-identical to `ray_box(og, dn, box, ·)[1]` (see the GLSL).
pub fn surf_block_exit(w: &Dda, l: [i32; 3], n: i32, shift: u32, r: u32) -> f32 {
    let (lo, hi) = surf_block_box(l, n, shift, r);
    let mut t = DDA_BIG;
    for a in 0..3 {
        if w.step[a] == 0 {
            continue;
        }
        let k = if w.step[a] > 0 { hi[a] } else { lo[a] };
        t = t.min((k - w.o[a]) * w.inv[a]);
    }
    t
}

/// Restarts walk `w` (started as `dda_init(og, dn, n, ·)`) at `t` ≥ its current entry t: the
/// state `dda_init(og, dn, n, t)` returns, without redoing the grid clip.
#[allow(clippy::neg_cmp_op_on_partial_ord)] // `!(a < b)` is true on NaN, as in the GLSL
pub fn surf_dda_restart(w: &mut Dda, dn: [f32; 3], n: i32, t: f32) {
    let d = dda_flush(dn);
    for a in 0..3 {
        let up = w.step[a].max(0);
        let p = w.o[a] + t * d[a];
        let mut c = p.clamp(-1.0, n as f32).floor() as i32;
        let tn = ((c + up) as f32 - w.o[a]) * w.inv[a];
        c += i32::from(tn <= t) * w.step[a];
        let tp = ((c + 1 - up) as f32 - w.o[a]) * w.inv[a];
        c -= i32::from(tp > t) * w.step[a];
        w.cell[a] = c.clamp(0, n - 2);
        let tx = ((w.cell[a] + up) as f32 - w.o[a]) * w.inv[a];
        w.t_next[a] = if d[a] != 0.0 { tx } else { DDA_BIG };
    }
    w.t = t;
    if !(t < w.t_end) {
        // Past the grid: the walk ends at the next dda_next.
        w.t_next = [DDA_BIG; 3];
        w.t = -DDA_BIG;
        w.t_end = -DDA_BIG;
    }
}

/// Called when the walk `w` (started as `dda_init(og, dn, n, ·)`) has just produced the piece of
/// cell `l` whose block `bi` has mask 0 and empty radius `r`: unless `bi` is the block skipped
/// last, restarts `w` at the exit of the cube of blocks within `r` of it, records `bi` in
/// `skipped` and returns true (drop the cell and continue with `dda_next`); returns false (walk
/// the cell as usual) when `bi == *skipped`.
#[allow(clippy::too_many_arguments)]
pub fn surf_block_skip(
    w: &mut Dda,
    dn: [f32; 3],
    n: i32,
    l: [i32; 3],
    bi: u32,
    skipped: &mut u32,
    shift: u32,
    r: u32,
) -> bool {
    if bi == *skipped {
        return false;
    }
    let t = surf_block_exit(w, l, n, shift, r);
    surf_dda_restart(w, dn, n, t);
    *skipped = bi;
    true
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

/// Bit i of word i/32 set when the cell whose lower corner is slot i (x-major, `n`³ slots) has
/// its 8 corners allocated: `surface_live_cells` reads these instead of the links.
pub fn complete_cells(links: &[i32], n: u32) -> Vec<u32> {
    if n < 2 {
        return vec![0; surf_live_words(n) as usize];
    }
    let n = n as usize;
    let (nz, nyz) = (n, n * n);
    (0..surf_live_words(n as u32) as usize)
        .into_par_iter()
        .map(|w| {
            let mut bits = 0u32;
            // The word's first slot's coordinates, then stepped along z (no division per slot).
            let s0 = 32 * w;
            let (mut x, mut y, mut z) = (s0 / nyz, (s0 / nz) % n, s0 % n);
            for b in 0..32 {
                let s = s0 + b;
                if x + 1 < n && y + 1 < n && z + 1 < n {
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
                        bits |= 1 << b;
                    }
                }
                z += 1;
                if z == n {
                    z = 0;
                    y += 1;
                    if y == n {
                        y = 0;
                        x += 1;
                    }
                }
            }
            bits
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::dda::{dda_init, dda_next, ray_box, ray_unit, DdaPiece};
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    /// A ray from far outside an `nf`-vertex grid towards a random point inside it: (origin,
    /// direction, not normalised).
    fn far_ray(rng: &mut Pcg64, nf: f32) -> ([f32; 3], [f32; 3]) {
        let o: [f32; 3] = std::array::from_fn(|_| rng.random_range(-3.0 * nf..4.0 * nf));
        let at: [f32; 3] = std::array::from_fn(|_| rng.random_range(0.0..nf - 1.0));
        (o, std::array::from_fn(|i| at[i] - o[i]))
    }

    /// The skipping walk's pieces, and the number of skips.
    fn skip_walk(
        og: [f32; 3],
        dn: [f32; 3],
        n: i32,
        blocks: &[u32],
        shift: u32,
    ) -> (Vec<DdaPiece>, usize) {
        let nb = surf_blocks_per_axis(n as u32, shift);
        let mut w = dda_init(og, dn, n, 0.0);
        let mut skipped = SURF_NO_BLOCK;
        let mut out = Vec::new();
        let mut skips = 0;
        while let Some(p) = dda_next(&mut w) {
            let bi = surf_block_index(p.cell, nb, shift);
            let word = blocks[bi as usize];
            if word & SURF_MASK_BITS == 0 {
                // The cheap exit and restart are the slab test and dda_init, bit for bit.
                let radius = word >> SURF_RADIUS_SHIFT;
                let (lo, hi) = surf_block_box(p.cell, n, shift, radius);
                let t_exit = ray_box(og, dn, lo, hi, p.t0)[1];
                assert_eq!(
                    surf_block_exit(&w, p.cell, n, shift, radius).to_bits(),
                    t_exit.to_bits()
                );
                let mut r = w;
                surf_dda_restart(&mut r, dn, n, t_exit);
                let want = dda_init(og, dn, n, t_exit);
                assert_eq!(format!("{r:?}"), format!("{want:?}"), "restart at {t_exit}");
                if surf_block_skip(&mut w, dn, n, p.cell, bi, &mut skipped, shift, radius) {
                    skips += 1;
                    continue;
                }
            }
            out.push(p);
        }
        (out, skips)
    }

    #[test]
    fn sizes_and_boxes() {
        assert_eq!(surf_blocks_per_axis(2, 3), 1);
        assert_eq!(surf_blocks_per_axis(9, 3), 1);
        assert_eq!(surf_blocks_per_axis(10, 3), 2);
        assert_eq!(surf_blocks_per_axis(129, 3), 16);
        assert_eq!(surf_blocks_per_axis(128, 3), 16);
        assert_eq!(surf_blocks_per_axis(5, 2), 1);
        assert_eq!(surf_blocks_per_axis(6, 2), 2);
        assert_eq!(surf_blocks_per_axis(128, 2), 32);
        assert_eq!(
            surf_block_box([9, 0, 15], 20, 3, 0),
            ([8.0, 0.0, 8.0], [16.0, 8.0, 16.0])
        );
        assert_eq!(
            surf_block_box([17, 16, 18], 20, 3, 0),
            ([16.0, 16.0, 16.0], [19.0, 19.0, 19.0])
        );
        assert_eq!(
            surf_block_box([9, 0, 15], 20, 2, 0),
            ([8.0, 0.0, 12.0], [12.0, 4.0, 16.0])
        );
        // Radius 1 and 2: clipped to the grid on both sides.
        assert_eq!(
            surf_block_box([9, 0, 15], 20, 2, 1),
            ([4.0, 0.0, 8.0], [16.0, 8.0, 19.0])
        );
        assert_eq!(
            surf_block_box([9, 5, 15], 40, 2, 2),
            ([0.0, 0.0, 4.0], [20.0, 16.0, 24.0])
        );
        assert_eq!(surf_block_index([17, 3, 9], 3, 3), 19);
        assert_eq!(surf_block_index([17, 3, 9], 5, 2), (4 * 5) * 5 + 2);
        assert_eq!(
            surf_block_mask(SURF_BLOCK_BIG, -SURF_BLOCK_BIG, 1.0, &[0.0]),
            0
        );
        assert_eq!(
            surf_block_mask(-1.0, 2.0, 0.5, &[-1.5, -1.6, 2.5, 2.6, 0.0]),
            0b10101
        );
    }

    /// The separable passes give each block without levels the largest cube of blocks without
    /// levels around it (brute force over every cube), capped, and leave the masks alone.
    #[test]
    fn block_radii_are_the_largest_empty_cubes() {
        let mut rng = Pcg64::seed_from_u64(5);
        for case in 0..300 {
            let nb = [1u32, 2, 3, 7, 12, 20][case % 6];
            let p_dead = [0.5, 0.9, 0.99, 1.0][case % 4];
            let masks: Vec<u32> = (0..nb * nb * nb)
                .map(|_| {
                    if rng.random::<f64>() >= p_dead {
                        rng.random_range(1..256)
                    } else {
                        0
                    }
                })
                .collect();
            let mut words = masks.clone();
            surf_block_radii(&mut words, nb);
            let at = |x: i64, y: i64, z: i64| masks[((x * nb as i64 + y) * nb as i64 + z) as usize];
            for b in 0..nb * nb * nb {
                let w = words[b as usize];
                assert_eq!(w & SURF_MASK_BITS, masks[b as usize]);
                if masks[b as usize] != 0 {
                    assert_eq!(w >> SURF_RADIUS_SHIFT, 0);
                    continue;
                }
                let c = [b / (nb * nb), (b / nb) % nb, b % nb].map(|v| v as i64);
                let empty = |r: i64| {
                    let rng_of = |a: usize| (c[a] - r).max(0)..=(c[a] + r).min(nb as i64 - 1);
                    rng_of(0).all(|x| rng_of(1).all(|y| rng_of(2).all(|z| at(x, y, z) == 0)))
                };
                let want = (0..=SURF_MAX_RADIUS as i64)
                    .take_while(|&r| empty(r))
                    .last()
                    .unwrap();
                assert_eq!(
                    (w >> SURF_RADIUS_SHIFT) as i64,
                    want,
                    "case {case}: nb {nb} block {c:?}"
                );
            }
        }
    }

    /// Random dead-block patterns (not derived from any field) and adversarial rays: the skipping
    /// walk yields exactly the continuous walk's pieces in live blocks, bit for bit.
    #[test]
    fn skipping_walk_reproduces_the_live_pieces() {
        let mut rng = Pcg64::seed_from_u64(3);
        let mut total_skips = 0;
        for case in 0..8000 {
            let n = [2, 9, 10, 17, 20, 33, 40][case % 7];
            // Both backends' block edges, 8 and 4.
            let shift = [SURF_BLOCK_SHIFT_CPU, SURF_BLOCK_SHIFT_VULKAN][(case / 7) % 2];
            let nb = surf_blocks_per_axis(n as u32, shift) as usize;
            let p_dead = [0.3, 0.7, 0.95][case % 3];
            let mut blocks: Vec<u32> = (0..nb * nb * nb)
                .map(|_| u32::from(rng.random::<f64>() >= p_dead))
                .collect();
            surf_block_radii(&mut blocks, nb as u32);
            let nf = n as f32;
            let bf =
                |rng: &mut Pcg64| (rng.random_range(0..=nb) << shift).min(n as usize - 1) as f32;
            let (og, d): ([f32; 3], [f32; 3]) = match case % 6 {
                // Axis-aligned along block faces / edges.
                0 => {
                    let a = rng.random_range(0..3);
                    let mut g = [bf(&mut rng), bf(&mut rng), rng.random_range(0.0..nf - 1.0)];
                    g[a] = -2.0;
                    let mut d = [0.0; 3];
                    d[a] = 1.0;
                    (g, d)
                }
                // Diagonals through block corners.
                1 => {
                    let v = [bf(&mut rng), bf(&mut rng), bf(&mut rng)];
                    let d = [1.0f32, -1.0, 1.0].map(|s| if rng.random() { s } else { -s });
                    (std::array::from_fn(|i| v[i] - 30.0 * d[i]), d)
                }
                // Starting inside a (possibly dead) block, random direction.
                2 => (
                    std::array::from_fn(|_| rng.random_range(0.0..nf - 1.0)),
                    std::array::from_fn(|_| rng.random_range(-1.0..1.0)),
                ),
                // Grazing a block face: in the plane x = Bk, tilted in y and z.
                3 => {
                    let mut g = [bf(&mut rng), -1.0, rng.random_range(0.0..nf - 1.0)];
                    g[1] = -1.5;
                    (g, [0.0, 1.0, rng.random_range(-0.3..0.3)])
                }
                // Starting on a block corner.
                4 => (
                    [bf(&mut rng), bf(&mut rng), bf(&mut rng)],
                    std::array::from_fn(|_| rng.random_range(-1.0..1.0)),
                ),
                // From far away.
                _ => far_ray(&mut rng, nf),
            };
            let dn = ray_unit(d);
            let live = |p: &DdaPiece| {
                blocks[surf_block_index(p.cell, nb as u32, shift) as usize] & SURF_MASK_BITS != 0
            };
            let want: Vec<DdaPiece> = dda_init(og, dn, n, 0.0).filter(live).collect();
            let (got, skips) = skip_walk(og, dn, n, &blocks, shift);
            assert_eq!(got, want, "case {case}: n {n} og {og:?} dn {dn:?}");
            total_skips += skips;
        }
        assert!(total_skips > 10000, "only {total_skips} skips");
    }

    /// Random allocated boxes (empty ones too) and adversarial rays (along the box's faces and
    /// edges, through its corners, from inside, from far away): the walk started at the box entry
    /// and ended at its exit yields exactly the continuous walk's pieces of the cells inside the
    /// box, bit for bit.
    #[test]
    fn box_clipped_walk_reproduces_the_pieces_inside() {
        let mut rng = Pcg64::seed_from_u64(7);
        let mut clipped_away = 0usize;
        for case in 0..6000 {
            let n = [2, 9, 17, 33, 40][case % 5];
            let mut b = [0u32; SURF_BOX_WORDS];
            for a in 0..3 {
                let (x, y) = (rng.random_range(0..n as u32), rng.random_range(0..n as u32));
                (b[a], b[3 + a]) = (x.min(y), x.max(y));
            }
            if case % 50 == 0 {
                b = [1, 1, 1, 0, 0, 0]; // nothing allocated
            }
            let nf = n as f32;
            let face = |rng: &mut Pcg64, a: usize| b[if rng.random() { a } else { 3 + a }] as f32;
            let (og, d): ([f32; 3], [f32; 3]) = match case % 5 {
                // Axis-aligned, in the planes of the box's faces.
                0 => {
                    let a = rng.random_range(0..3);
                    let mut g: [f32; 3] = std::array::from_fn(|i| face(&mut rng, i));
                    g[a] = -2.0;
                    let mut d = [0.0; 3];
                    d[a] = 1.0;
                    (g, d)
                }
                // Diagonals through the box's corners.
                1 => {
                    let v: [f32; 3] = std::array::from_fn(|i| face(&mut rng, i));
                    let d = [1.0f32, -1.0, 1.0].map(|s| if rng.random() { s } else { -s });
                    (std::array::from_fn(|i| v[i] - 30.0 * d[i]), d)
                }
                // Grazing a face: in the plane of one, tilted in the other two.
                2 => {
                    let a = rng.random_range(0..3);
                    let mut g: [f32; 3] = std::array::from_fn(|_| -1.5);
                    g[a] = face(&mut rng, a);
                    let mut d: [f32; 3] = std::array::from_fn(|_| rng.random_range(0.1..1.0));
                    d[a] = 0.0;
                    (g, d)
                }
                // From inside the grid.
                3 => (
                    std::array::from_fn(|_| rng.random_range(0.0..nf - 1.0)),
                    std::array::from_fn(|_| rng.random_range(-1.0..1.0)),
                ),
                // From far away.
                _ => far_ray(&mut rng, nf),
            };
            let dn = ray_unit(d);
            let inside = |p: &DdaPiece| {
                (0..3).all(|a| b[a] as i32 <= p.cell[a] && p.cell[a] < b[3 + a] as i32)
            };
            let want: Vec<DdaPiece> = dda_init(og, dn, n, 0.0).filter(inside).collect();
            let [t_in, t_out] = surf_box_span(og, dn, &b);
            let start = if t_in < t_out { t_in } else { DDA_BIG };
            let clipped: Vec<DdaPiece> = dda_init(og, dn, n, start)
                .take_while(|p| p.t0 < t_out)
                .collect();
            let got: Vec<DdaPiece> = clipped.iter().copied().filter(inside).collect();
            clipped_away += dda_init(og, dn, n, 0.0).count() - clipped.len();
            assert_eq!(
                got, want,
                "case {case}: n {n} box {b:?} og {og:?} dn {dn:?}"
            );
        }
        assert!(
            clipped_away > 20_000,
            "only {clipped_away} pieces clipped away"
        );
    }
}
