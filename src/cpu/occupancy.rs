//! Twin of `glsl/occupancy.comp`: the occupancy words of the stage-1 skip structure.

use crate::grid::row_slots;
use crate::math::plenoxel::{occ_dims, SIGMA_EPS};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, Ordering};

/// Twin of `occupancy.comp` (with `shift` = `OCC_SHIFT`): 1 for each 2^shift-cell block whose
/// vertex box (the block's cells' corners) holds an allocated vertex with density above
/// SIGMA_EPS/2, else 0. The kernel looks at each block's box; this scatters from the allocated
/// rows instead ([`occupancy_rows`]), which gives the same words and reads no links.
pub fn occupancy(links: &[i32], density: &[f32], res: [u32; 3], shift: u32) -> Vec<u32> {
    occupancy_rows(&occupancy_slots(links, density.len()), density, res, shift)
}

/// The slot of each of `rows` rows (`grid::row_slots`), `u32::MAX` for a row no link names: what
/// [`occupancy_rows`] scatters from. The allocation alone decides it: a training loop keeps it.
pub fn occupancy_slots(links: &[i32], rows: usize) -> Vec<u32> {
    let mut slots = row_slots(links, rows);
    for (r, s) in slots.iter_mut().enumerate() {
        if links.get(*s as usize) != Some(&(r as i32)) {
            *s = u32::MAX;
        }
    }
    slots
}

/// [`occupancy`] from the rows' slots ([`occupancy_slots`]): each row above the threshold that
/// has a slot marks the blocks whose vertex box holds it — along each axis, the block of its
/// cell, and the block before when the vertex is that block's far corner (x a multiple of
/// 2^shift).
pub fn occupancy_rows(slots: &[u32], density: &[f32], res: [u32; 3], shift: u32) -> Vec<u32> {
    let nb = occ_dims(res, shift);
    let occ: Vec<AtomicU32> = (0..nb[0] * nb[1] * nb[2])
        .map(|_| AtomicU32::new(0))
        .collect();
    let mask = (1u32 << shift) - 1;
    slots
        .par_iter()
        .zip(density.par_iter())
        .filter(|&(&s, &d)| s != u32::MAX && d > 0.5 * SIGMA_EPS)
        .for_each(|(&s, _)| {
            let v = [s / (res[1] * res[2]), (s / res[2]) % res[1], s % res[2]];
            // The blocks along each axis: v >> shift (when it is a block: the last vertex
            // of an axis whose cells fill the blocks is no block's first corner), and the one
            // before at a block boundary.
            let axis = |i: usize| {
                let b = v[i] >> shift;
                let own = (b < nb[i]).then_some(b);
                let before = (v[i] & mask == 0 && b > 0).then(|| b - 1);
                [own, before]
            };
            let (ax, ay, az) = (axis(0), axis(1), axis(2));
            for bx in ax.into_iter().flatten() {
                for by in ay.into_iter().flatten() {
                    for bz in az.into_iter().flatten() {
                        let o = &occ[((bx * nb[1] + by) * nb[2] + bz) as usize];
                        if o.load(Ordering::Relaxed) == 0 {
                            o.store(1, Ordering::Relaxed);
                        }
                    }
                }
            }
        });
    occ.into_iter().map(AtomicU32::into_inner).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::plenoxel::{OCC_SHIFT, OCC_SHIFT_CPU};
    use rand::{Rng, SeedableRng};

    /// Each block's word by its definition: a scan of its vertex box.
    fn by_definition(links: &[i32], density: &[f32], res: [u32; 3], shift: u32) -> Vec<u32> {
        let nb = occ_dims(res, shift);
        let mut out = Vec::new();
        for bx in 0..nb[0] {
            for by in 0..nb[1] {
                for bz in 0..nb[2] {
                    let lo = [bx, by, bz].map(|b| b << shift);
                    let hi: [u32; 3] =
                        std::array::from_fn(|i| (lo[i] + (1 << shift)).min(res[i] - 1));
                    let mut any = 0;
                    for x in lo[0]..=hi[0] {
                        for y in lo[1]..=hi[1] {
                            for z in lo[2]..=hi[2] {
                                let l = links[((x * res[1] + y) * res[2] + z) as usize];
                                if l >= 0 && density[l as usize] > 0.5 * SIGMA_EPS {
                                    any = 1;
                                }
                            }
                        }
                    }
                    out.push(any);
                }
            }
        }
        out
    }

    #[test]
    fn occupancy_from_the_rows_is_the_box_scan() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
        // Axes whose cells do and do not fill their blocks (17 vertices: 16 cells, two blocks;
        // 20: 19 cells; 9: one block), sparse and dense allocations, rows no link names.
        for res in [[17u32, 20, 9], [9, 17, 26], [2, 2, 2]] {
            for (alloc, above) in [(0.05f32, 0.5f32), (0.6, 0.1), (1.0, 0.02)] {
                let slots = (res[0] * res[1] * res[2]) as usize;
                let mut links = vec![-1i32; slots];
                let mut rows = 0;
                for l in links.iter_mut() {
                    if rng.random::<f32>() < alloc {
                        *l = rows;
                        rows += 1;
                    }
                }
                // Two rows more than the links name: never occupy anything.
                let density: Vec<f32> = (0..rows + 2)
                    .map(|_| {
                        if rng.random::<f32>() < above {
                            SIGMA_EPS
                        } else {
                            0.5 * SIGMA_EPS
                        }
                    })
                    .collect();
                for shift in [OCC_SHIFT, OCC_SHIFT_CPU] {
                    let want = by_definition(&links, &density, res, shift);
                    let got = occupancy(&links, &density, res, shift);
                    assert_eq!(got, want, "{res:?} {alloc} shift {shift}");
                    assert!(want.contains(&1) || rows == 0 || above < 0.05);
                }
            }
        }
        // One vertex alone above the threshold, at block boundaries (shared by two blocks per
        // axis), inside a block and on the grid's last vertex.
        let res = [17u32, 20, 9];
        for v in [
            [8u32, 8, 8],
            [0, 0, 0],
            [16, 19, 8],
            [8, 3, 0],
            [5, 16, 8],
            [16, 8, 4],
        ] {
            let mut links = vec![-1i32; (res[0] * res[1] * res[2]) as usize];
            links[((v[0] * res[1] + v[1]) * res[2] + v[2]) as usize] = 0;
            // A second row above the threshold that no link names occupies nothing.
            let density = [SIGMA_EPS; 2];
            for shift in [OCC_SHIFT, OCC_SHIFT_CPU] {
                let want = by_definition(&links, &density, res, shift);
                let got = occupancy(&links, &density, res, shift);
                assert_eq!(got, want, "vertex {v:?} shift {shift}");
            }
        }
    }
}
