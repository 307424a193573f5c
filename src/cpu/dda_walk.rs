//! Twin of `glsl/dda_walk.comp`: walks each ray through the cells of an `n`³-vertex grid.

use crate::math::dda::{dda_cell_index, dda_hash, dda_init, DDA_HASH0};
use rayon::prelude::*;

/// One ray: writes `[count, checksum]` to `stats` and the first `cells.len()` cells with their
/// `[t0, t1]` to `cells` / `ts`.
fn walk_one(ray: &[f32], n: u32, t_min: f32, stats: &mut [u32], cells: &mut [u32], ts: &mut [f32]) {
    let o = [ray[0], ray[1], ray[2]];
    let d = [ray[3], ray[4], ray[5]];
    let mut count = 0usize;
    let mut h = DDA_HASH0;
    for piece in dda_init(o, d, n as i32, t_min) {
        let idx = dda_cell_index(piece.cell, n);
        h = dda_hash(h, idx);
        if count < cells.len() {
            cells[count] = idx;
            ts[2 * count] = piece.t0;
            ts[2 * count + 1] = piece.t1;
        }
        count += 1;
    }
    stats[0] = count as u32;
    stats[1] = h;
}

/// `rays`: 6 floats per ray (o, d in grid units); `stats`: 2 per ray (cells visited, checksum);
/// `cells`: `k` per ray (leading cell indices); `ts`: `2k` per ray (their entry and exit t).
/// Entries past a ray's count are left untouched, as in the kernel.
pub fn dda_walk(
    rays: &[f32],
    n: u32,
    k: u32,
    t_min: f32,
    stats: &mut [u32],
    cells: &mut [u32],
    ts: &mut [f32],
) {
    let n_rays = rays.len() / 6;
    let k = k as usize;
    assert_eq!(stats.len(), 2 * n_rays, "dda_walk: stats length");
    assert_eq!(cells.len(), k * n_rays, "dda_walk: cells length");
    assert_eq!(ts.len(), 2 * k * n_rays, "dda_walk: ts length");
    let rays = rays.par_chunks_exact(6).zip(stats.par_chunks_exact_mut(2));
    if k == 0 {
        rays.for_each(|(r, st)| walk_one(r, n, t_min, st, &mut [], &mut []));
    } else {
        rays.zip(cells.par_chunks_exact_mut(k))
            .zip(ts.par_chunks_exact_mut(2 * k))
            .for_each(|(((r, st), c), t)| walk_one(r, n, t_min, st, c, t));
    }
}
