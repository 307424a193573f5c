//! Twins of the stage-1 kernels `occupancy`, `plenoxel_fwd`, `plenoxel_train` and
//! `plenoxel_weights`: one rayon task per ray (per block for occupancy), the same march
//! (`math::plenoxel`) and the same gradient formulation; scatters use CAS float atomics.

use super::atomic;
use super::step::touch;
use crate::grid::row_slots;
use crate::math::plenoxel::{
    march_init, march_next, occ_dims, sample_alpha, sample_at, sample_color_raw, GridRef, March,
    PlenoxelCounts, OCC_SHIFT, SIGMA_EPS,
};
use crate::math::sh::sh_basis;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, Ordering};

use crate::abi::consts::REPLAY;

/// How rays map into the grid and when they stop.
#[derive(Clone, Copy, Debug)]
pub struct MarchParams {
    /// grid = p·scale + offset (per axis).
    pub scale: [f32; 3],
    pub offset: [f32; 3],
    /// Stop once transmittance falls below this.
    pub stop_thresh: f32,
}

fn ray(rays: &[f32], r: usize) -> ([f32; 3], [f32; 3]) {
    let v = &rays[6 * r..6 * r + 6];
    ([v[0], v[1], v[2]], [v[3], v[4], v[5]])
}

/// Twin of `occupancy.comp`: 1 for each 2^OCC_SHIFT-cell block whose vertex box (the block's
/// cells' corners) holds an allocated vertex with density above SIGMA_EPS/2, else 0. The kernel
/// looks at each block's box; this scatters from the allocated rows instead ([`occupancy_rows`]),
/// which gives the same words and reads no links.
pub fn occupancy(links: &[i32], density: &[f32], res: [u32; 3]) -> Vec<u32> {
    occupancy_rows(&occupancy_slots(links, density.len()), density, res)
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
/// 2^OCC_SHIFT).
pub fn occupancy_rows(slots: &[u32], density: &[f32], res: [u32; 3]) -> Vec<u32> {
    let nb = occ_dims(res);
    let occ: Vec<AtomicU32> = (0..nb[0] * nb[1] * nb[2])
        .map(|_| AtomicU32::new(0))
        .collect();
    let mask = (1u32 << OCC_SHIFT) - 1;
    slots
        .par_iter()
        .zip(density.par_iter())
        .filter(|&(&s, &d)| s != u32::MAX && d > 0.5 * SIGMA_EPS)
        .for_each(|(&s, _)| {
            let v = [s / (res[1] * res[2]), (s / res[2]) % res[1], s % res[2]];
            // The blocks along each axis: v >> OCC_SHIFT (when it is a block: the last vertex
            // of an axis whose cells fill the blocks is no block's first corner), and the one
            // before at a block boundary.
            let axis = |i: usize| {
                let b = v[i] >> OCC_SHIFT;
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

/// The forward march of one ray (both kernels' first loop): accumulated colour (background not
/// yet added) and final transmittance; the indices of the first REPLAY shaded samples go to
/// `replay`, and the number of shaded samples to `counts.shaded`.
fn forward(
    g: &GridRef,
    m: &March,
    y: &[f32; 9],
    stop_thresh: f32,
    counts: &mut PlenoxelCounts,
    replay: &mut [u32; REPLAY],
) -> ([f32; 3], f32) {
    let mut color = [0f32; 3];
    let mut t_acc = 1.0f32;
    let mut k = 0;
    while let Some(s) = march_next(g, m, &mut k, counts) {
        if (counts.shaded as usize) < REPLAY {
            replay[counts.shaded as usize] = k - 1;
        }
        counts.shaded += 1;
        let alpha = sample_alpha(s.sigma, m.delta);
        let c = sample_color_raw(g, &s.lk, &s.w, y).map(|x| x.max(0.0));
        let wt = t_acc * alpha;
        for ch in 0..3 {
            color[ch] += wt * c[ch];
        }
        t_acc *= 1.0 - alpha;
        if t_acc < stop_thresh {
            break;
        }
    }
    (color, t_acc)
}

/// Twin of `plenoxel_fwd.comp`: rgb per ray (composited on `bg`) and the summed sample counts.
pub fn render(
    g: &GridRef,
    rays: &[f32],
    mp: &MarchParams,
    bg: [f32; 3],
) -> (Vec<f32>, PlenoxelCounts) {
    let n = rays.len() / 6;
    let out: Vec<([f32; 3], PlenoxelCounts)> = (0..n)
        .into_par_iter()
        .map(|r| {
            let (ro, rd) = ray(rays, r);
            let mut counts = PlenoxelCounts::default();
            let (color, t_acc) = match march_init(ro, rd, mp.scale, mp.offset, g.res) {
                Some(m) => forward(
                    g,
                    &m,
                    &sh_basis(rd),
                    mp.stop_thresh,
                    &mut counts,
                    &mut [0; REPLAY],
                ),
                None => ([0.0; 3], 1.0),
            };
            (std::array::from_fn(|ch| color[ch] + t_acc * bg[ch]), counts)
        })
        .collect();
    let counts = out.iter().fold(PlenoxelCounts::default(), |a, o| a + o.1);
    (out.into_iter().flat_map(|o| o.0).collect(), counts)
}

/// Gradient outputs of one training pass, and the per-vertex touched flags.
pub struct TrainGrads<'a> {
    pub density: &'a mut [f32],
    pub sh: &'a mut [f32],
    pub touched: &'a mut [u32],
    /// dL/dbg (a learned background), or `None` (fixed: not accumulated).
    pub background: Option<&'a mut [f32; 3]>,
}

/// Twin of `plenoxel_train.comp`: returns per-ray squared error and the sample counts, adds
/// dL/dσ and dL/dSH (dL/dC = grad_scale·(C − target), C composited on `bg`) into `grads`, and
/// dL/dbg = Σ_rays dL/dC·T when `grads.background` is given.
pub fn train(
    g: &GridRef,
    rays: &[f32],
    targets: &[f32],
    mp: &MarchParams,
    grad_scale: f32,
    bg: [f32; 3],
    grads: TrainGrads,
) -> (Vec<f32>, PlenoxelCounts) {
    let n = rays.len() / 6;
    let gd = atomic::as_atomic(grads.density);
    let gs = atomic::as_atomic(grads.sh);
    let touched = atomic::as_atomic_u32(grads.touched);
    let out: Vec<(f32, [f32; 3], PlenoxelCounts)> = (0..n)
        .into_par_iter()
        .map(|r| {
            let (ro, rd) = ray(rays, r);
            let target = [targets[3 * r], targets[3 * r + 1], targets[3 * r + 2]];
            let y = sh_basis(rd);
            let m = march_init(ro, rd, mp.scale, mp.offset, g.res);
            let mut counts = PlenoxelCounts::default();
            let mut replay = [0u32; REPLAY];
            let (color, t_acc) = match &m {
                Some(m) => forward(g, m, &y, mp.stop_thresh, &mut counts, &mut replay),
                None => ([0.0; 3], 1.0),
            };
            let shaded = counts.shaded as usize;
            let total: [f32; 3] = std::array::from_fn(|ch| color[ch] + t_acc * bg[ch]);
            let diff: [f32; 3] = std::array::from_fn(|ch| total[ch] - target[ch]);
            let loss = diff[0] * diff[0] + diff[1] * diff[1] + diff[2] * diff[2];
            let g_c = diff.map(|d| grad_scale * d);
            let g_bg = g_c.map(|gc| gc * t_acc);

            let Some(m) = &m else {
                return (loss, g_bg, counts);
            };
            let mut scatter = CellAccumulator::new(gd, gs, touched, &y);
            let mut accum = [0f32; 3];
            let mut t_acc = 1.0f32;
            let mut k = 0;
            let mut ignored = PlenoxelCounts::default();
            for j in 0.. {
                let s = if shaded <= REPLAY {
                    if j == shaded {
                        break;
                    }
                    sample_at(g, m, replay[j])
                } else {
                    match march_next(g, m, &mut k, &mut ignored) {
                        Some(s) => s,
                        None => break,
                    }
                };
                let alpha = sample_alpha(s.sigma, m.delta);
                let raw = sample_color_raw(g, &s.lk, &s.w, &y);
                let c = raw.map(|x| x.max(0.0));
                let wt = t_acc * alpha;
                for ch in 0..3 {
                    accum[ch] += wt * c[ch];
                }
                let tn = t_acc * (1.0 - alpha);
                let dsig3: [f32; 3] =
                    std::array::from_fn(|ch| g_c[ch] * (tn * c[ch] - (total[ch] - accum[ch])));
                let d_sigma = m.delta * (dsig3[0] + dsig3[1] + dsig3[2]);
                let d_color: [f32; 3] =
                    std::array::from_fn(|ch| if raw[ch] > 0.0 { g_c[ch] * wt } else { 0.0 });
                counts.atomic_adds += scatter.add(s.l, &s.lk, &s.w, d_sigma, d_color);
                t_acc = tn;
                if t_acc < mp.stop_thresh {
                    break;
                }
            }
            counts.atomic_adds += scatter.flush();
            (loss, g_bg, counts)
        })
        .collect();
    if let Some(gb) = grads.background {
        for o in &out {
            for ch in 0..3 {
                gb[ch] += o.1[ch];
            }
        }
    }
    let counts = out.iter().fold(PlenoxelCounts::default(), |a, o| a + o.2);
    (out.into_iter().map(|o| o.0).collect(), counts)
}

/// Per-cell gradient accumulator of the train twin (the kernel's `flush`).
struct CellAccumulator<'a> {
    gd: &'a [AtomicU32],
    gs: &'a [AtomicU32],
    touched: &'a [AtomicU32],
    y: &'a [f32; 9],
    cell: [i32; 3],
    lk: [i32; 8],
    sigma: [f32; 8],
    color: [[f32; 3]; 8],
}

impl<'a> CellAccumulator<'a> {
    fn new(
        gd: &'a [AtomicU32],
        gs: &'a [AtomicU32],
        touched: &'a [AtomicU32],
        y: &'a [f32; 9],
    ) -> Self {
        CellAccumulator {
            gd,
            gs,
            touched,
            y,
            cell: [-1; 3],
            lk: [-1; 8],
            sigma: [0.0; 8],
            color: [[0.0; 3]; 8],
        }
    }

    fn add(
        &mut self,
        cell: [i32; 3],
        lk: &[i32; 8],
        w: &[f32; 8],
        d_sigma: f32,
        d_color: [f32; 3],
    ) -> u32 {
        let mut adds = 0;
        if cell != self.cell {
            adds = self.flush();
            self.cell = cell;
            self.lk = *lk;
        }
        for i in 0..8 {
            self.sigma[i] += w[i] * d_sigma;
            for ch in 0..3 {
                self.color[i][ch] += w[i] * d_color[ch];
            }
        }
        adds
    }

    /// Add the accumulators to the gradients; returns the number of atomic adds.
    fn flush(&mut self) -> u32 {
        let mut adds = 0;
        for i in 0..8 {
            let l = self.lk[i];
            let (gsig, gcol) = (self.sigma[i], self.color[i]);
            self.sigma[i] = 0.0;
            self.color[i] = [0.0; 3];
            if l < 0 || (gsig == 0.0 && gcol == [0.0; 3]) {
                continue;
            }
            touch(self.touched, l as usize);
            if gsig != 0.0 {
                atomic::add(&self.gd[l as usize], gsig);
                adds += 1;
            }
            for ch in 0..3 {
                if gcol[ch] == 0.0 {
                    continue;
                }
                let row = l as usize * 27 + ch * 9;
                for k in 0..9 {
                    atomic::add(&self.gs[row + k], gcol[ch] * self.y[k]);
                }
                adds += 9;
            }
        }
        adds
    }
}

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

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Each block's word by its definition: a scan of its vertex box.
    fn by_definition(links: &[i32], density: &[f32], res: [u32; 3]) -> Vec<u32> {
        let nb = occ_dims(res);
        let mut out = Vec::new();
        for bx in 0..nb[0] {
            for by in 0..nb[1] {
                for bz in 0..nb[2] {
                    let lo = [bx, by, bz].map(|b| b << OCC_SHIFT);
                    let hi: [u32; 3] =
                        std::array::from_fn(|i| (lo[i] + (1 << OCC_SHIFT)).min(res[i] - 1));
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
                let want = by_definition(&links, &density, res);
                assert_eq!(occupancy(&links, &density, res), want, "{res:?} {alloc}");
                assert!(want.contains(&1) || rows == 0 || above < 0.05);
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
            let want = by_definition(&links, &density, res);
            assert_eq!(occupancy(&links, &density, res), want, "vertex {v:?}");
        }
    }
}
