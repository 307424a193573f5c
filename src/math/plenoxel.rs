//! The stage-1 ray march: the twin of `glsl/lib/plenoxel.glsl`, operation for operation (no FMA
//! contraction on either side), so the CPU twins `cpu::plenoxel_fwd`, `cpu::plenoxel_train` and
//! `cpu::plenoxel_weights` visit the same samples.

use super::dda::ray_box;
use super::trilerp::{cell_links, trilerp_weights};
use crate::abi::consts::REPLAY;

pub use crate::abi::consts::{OCC_SHIFT, SIGMA_EPS, SKIP_MARGIN, STEP};

/// The CPU twins' occupancy blocks are 2^OCC_SHIFT_CPU cells per axis: finer than the kernels'
/// (`OCC_SHIFT`), because a CPU sample in an empty cell of an occupied block costs its corners'
/// cache misses, and a skip only a few divisions (docs/results.md, "Stage-1 CPU twins: 4³
/// occupancy blocks"). Skipping passes over only samples with σ ≤ SIGMA_EPS, so the edge
/// changes no result.
pub const OCC_SHIFT_CPU: u32 = 2;

/// Borrowed view of a sparse grid and its occupancy volume.
#[derive(Clone, Copy)]
pub struct GridRef<'a> {
    pub res: [u32; 3],
    pub links: &'a [i32],
    pub density: &'a [f32],
    pub sh: &'a [f32],
    pub occ: &'a [u32],
    /// `occ`'s blocks are 2^occ_shift cells per axis.
    pub occ_shift: u32,
}

/// A ray in grid units with its lattice of samples.
#[derive(Clone, Copy, Debug)]
pub struct March {
    pub o: [f32; 3],
    pub d: [f32; 3],
    pub t0: f32,
    pub t_end: f32,
    /// World length of one 0.5-voxel step.
    pub delta: f32,
}

/// Set up the march of scene ray (ro, rd) with grid = p·scale + offset; `None` if it misses.
pub fn march_init(
    ro: [f32; 3],
    rd: [f32; 3],
    scale: [f32; 3],
    offset: [f32; 3],
    res: [u32; 3],
) -> Option<March> {
    let og: [f32; 3] = std::array::from_fn(|i| ro[i] * scale[i] + offset[i]);
    let dg: [f32; 3] = std::array::from_fn(|i| rd[i] * scale[i]);
    let len = (dg[0] * dg[0] + dg[1] * dg[1] + dg[2] * dg[2]).sqrt();
    let dn = dg.map(|x| x / len);
    let hi = res.map(|r| r as f32 - 0.5);
    let [t0, t_end] = ray_box(og, dn, [-0.5; 3], hi, 0.0);
    (t0 < t_end).then_some(March {
        o: og,
        d: dn,
        t0,
        t_end,
        delta: STEP / len,
    })
}

/// t of sample k.
pub fn march_t(m: &March, k: u32) -> f32 {
    m.t0 + STEP * k as f32
}

/// Cell and local position of the sample at t.
pub fn march_cell(m: &March, t: f32, res: [u32; 3]) -> ([i32; 3], [f32; 3]) {
    let mut l = [0i32; 3];
    let mut p = [0f32; 3];
    for i in 0..3 {
        let pos = (m.o[i] + m.d[i] * t).clamp(0.0, (res[i] - 1) as f32);
        l[i] = (pos.floor() as i32).min(res[i] as i32 - 2);
        p[i] = pos - l[i] as f32;
    }
    (l, p)
}

/// Blocks per axis of an occupancy volume of 2^shift-cell blocks.
pub fn occ_dims(res: [u32; 3], shift: u32) -> [u32; 3] {
    let b = 1u32 << shift;
    res.map(|r| (r - 1 + b - 1) >> shift)
}

/// Next sample index to look at when the sample in cell l lies in an empty block, else k.
pub fn march_skip(g: &GridRef, m: &March, k: u32, l: [i32; 3]) -> u32 {
    let b = l.map(|x| (x as u32) >> g.occ_shift);
    let nb = occ_dims(g.res, g.occ_shift);
    if g.occ[((b[0] * nb[1] + b[1]) * nb[2] + b[2]) as usize] != 0 {
        return k;
    }
    let bs = (1u32 << g.occ_shift) as f32;
    let mut t_exit = f32::MAX;
    for a in 0..3 {
        if m.d[a] != 0.0 {
            let lo = b[a] as f32 * bs;
            let hi = (lo + bs).min((g.res[a] - 1) as f32);
            let ta = (if m.d[a] > 0.0 { hi } else { lo } - m.o[a]) / m.d[a];
            t_exit = t_exit.min(ta);
        }
    }
    let next = ((t_exit - SKIP_MARGIN - m.t0) / STEP).ceil();
    if !(next < 4.0e9) {
        return u32::MAX;
    }
    (k + 1).max(next.max(0.0) as u32)
}

/// σ at trilinear weights w (unallocated corners count 0).
pub fn sample_sigma(g: &GridRef, lk: &[i32; 8], w: &[f32; 8]) -> f32 {
    let mut s = 0.0f32;
    for i in 0..8 {
        if lk[i] >= 0 {
            s += w[i] * g.density[lk[i] as usize];
        }
    }
    s
}

/// Pre-ReLU colour Σ_k Y_k·sh_k + 0.5 per channel.
pub fn sample_color_raw(g: &GridRef, lk: &[i32; 8], w: &[f32; 8], y: &[f32; 9]) -> [f32; 3] {
    let mut c = [0f32; 27];
    for i in 0..8 {
        if lk[i] < 0 {
            continue;
        }
        let row = &g.sh[lk[i] as usize * 27..lk[i] as usize * 27 + 27];
        for k in 0..27 {
            c[k] += w[i] * row[k];
        }
    }
    std::array::from_fn(|ch| {
        let mut acc = 0.5f32;
        for k in 0..9 {
            acc += y[k] * c[ch * 9 + k];
        }
        acc
    })
}

/// α = 1 − exp(−σΔ).
pub fn sample_alpha(sigma: f32, delta: f32) -> f32 {
    1.0 - (-sigma * delta).exp()
}

/// One shaded sample.
#[derive(Clone, Copy, Debug)]
pub struct Sample {
    pub l: [i32; 3],
    pub lk: [i32; 8],
    pub w: [f32; 8],
    pub sigma: f32,
}

pub use crate::abi::buffers::PlenoxelCounts;

/// Corner links, trilinear weights and σ of the sample in cell l at local position p.
fn sample_fill(g: &GridRef, l: [i32; 3], p: [f32; 3]) -> Sample {
    let lk = cell_links(g.links, g.res, l);
    let w = trilerp_weights(p);
    let sigma = sample_sigma(g, &lk, &w);
    Sample { l, lk, w, sigma }
}

/// The sample of index k (a replay of one that `march_next` returned).
pub fn sample_at(g: &GridRef, m: &March, k: u32) -> Sample {
    let (l, p) = march_cell(m, march_t(m, k), g.res);
    sample_fill(g, l, p)
}

/// Advance from sample k to the next sample with σ > SIGMA_EPS (twin of `march_next`).
pub fn march_next(
    g: &GridRef,
    m: &March,
    k: &mut u32,
    counts: &mut PlenoxelCounts,
) -> Option<Sample> {
    loop {
        let t = march_t(m, *k);
        if !(t < m.t_end) {
            return None;
        }
        let (l, p) = march_cell(m, t, g.res);
        let next = march_skip(g, m, *k, l);
        if next != *k {
            if !(march_t(m, next) < m.t_end) {
                counts.skipped += ((m.t_end - t) / STEP).ceil() as u32;
                return None;
            }
            counts.skipped += next - *k;
            *k = next;
            continue;
        }
        *k += 1;
        let s = sample_fill(g, l, p);
        if s.sigma > SIGMA_EPS {
            return Some(s);
        }
        counts.empty += 1;
    }
}

/// Origin and direction of ray `r` of `rays` (6 floats each).
pub fn ray(rays: &[f32], r: usize) -> ([f32; 3], [f32; 3]) {
    let v = &rays[6 * r..6 * r + 6];
    ([v[0], v[1], v[2]], [v[3], v[4], v[5]])
}

/// The forward march of one ray (the first loop of `plenoxel_fwd` and `plenoxel_train`): accumulated colour (background not
/// yet added) and final transmittance; the indices of the first REPLAY shaded samples go to
/// `replay`, and the number of shaded samples to `counts.shaded`.
pub fn forward(
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

/// How rays map into the grid and when they stop.
#[derive(Clone, Copy, Debug)]
pub struct MarchParams {
    /// grid = p·scale + offset (per axis).
    pub scale: [f32; 3],
    pub offset: [f32; 3],
    /// Stop once transmittance falls below this.
    pub stop_thresh: f32,
}

/// The loss weights of a stage-1 training pass (`plenoxel_train` and its twin).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LossWeights {
    /// dL/dC = grad_scale·(C − target).
    pub grad_scale: f32,
    /// λ of the Cauchy sparsity loss λ·Σ log(1 + 2σ²) over every shaded sample of the backward
    /// march (svox2's `lambda_sparsity`, from SNeRG); 0: none.
    pub sparsity: f32,
}

/// d/dσ of the sparsity loss of one sample, λ·4σ/(1 + 2σ²) (the kernel's arithmetic).
pub fn sparsity_grad(lambda: f32, sigma: f32) -> f32 {
    let den = 1.0 + 2.0 * (sigma * sigma);
    lambda * (4.0 * sigma / den)
}
