//! Twin of `glsl/plenoxel_train.comp`: one rayon task per ray, the forward march of
//! `plenoxel_fwd` and the same gradient formulation; scatters use CAS float atomics.

use crate::abi::consts::REPLAY;
use crate::math::atomic;
use crate::math::background_msi::{backward, BackgroundView};
use crate::math::plenoxel::{
    forward, march_init, march_next, ray, sample_alpha, sample_at, sample_color_raw, sparsity_grad,
    GridRef, LossWeights, MarchParams, PlenoxelCounts,
};
use crate::math::sh::sh_basis;
use crate::math::step::touch;
use rayon::prelude::*;
use std::sync::atomic::AtomicU32;

/// Gradient outputs of one training pass, and the per-vertex touched flags.
pub struct TrainGrads<'a> {
    pub density: &'a mut [f32],
    pub sh: &'a mut [f32],
    pub touched: &'a mut [u32],
    /// dL/dbg (a learned background colour), or `None` (fixed: not accumulated).
    pub background: Option<&'a mut [f32; 3]>,
    /// dL/d(texel values) of learned background spheres, or `None`.
    pub spheres: Option<&'a mut [f32]>,
}

/// Twin of `plenoxel_train.comp`: returns per-ray squared error and the sample counts, adds
/// dL/dσ and dL/dSH (dL/dC = `w.grad_scale`·(C − target), C = C_grid + T·B, B what `bg` puts
/// behind the ray; dL/dσ += `w.sparsity`·4σ/(1 + 2σ²) at every sample of the backward march)
/// into `grads`, dL/dbg = Σ_rays dL/dC·T·T_L when `grads.background` is given,
/// and the spheres' texel gradient (`math::background_msi::backward` with dL/dB = dL/dC·T) when
/// `grads.spheres` is.
pub fn train(
    g: &GridRef,
    rays: &[f32],
    targets: &[f32],
    mp: &MarchParams,
    w: LossWeights,
    bg: &BackgroundView,
    grads: TrainGrads,
) -> (Vec<f32>, PlenoxelCounts) {
    let n = rays.len() / 6;
    let gd = atomic::as_atomic(grads.density);
    let gs = atomic::as_atomic(grads.sh);
    let touched = atomic::as_atomic_u32(grads.touched);
    let sphere_grad = grads.spheres.map(atomic::as_atomic);
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
            let (behind, t_bg) = bg.behind(ro, rd);
            let total: [f32; 3] = std::array::from_fn(|ch| color[ch] + t_acc * behind[ch]);
            let diff: [f32; 3] = std::array::from_fn(|ch| total[ch] - target[ch]);
            let loss = diff[0] * diff[0] + diff[1] * diff[1] + diff[2] * diff[2];
            let g_c = diff.map(|d| w.grad_scale * d);
            let g_behind = g_c.map(|gc| gc * t_acc);
            let g_bg = g_behind.map(|g| g * t_bg);
            if let (Some(grad), Some((s, table))) = (sphere_grad, bg.spheres) {
                backward(s, table, grad, ro, rd, behind, g_behind);
            }

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
                let mut d_sigma = m.delta * (dsig3[0] + dsig3[1] + dsig3[2]);
                if w.sparsity > 0.0 {
                    d_sigma += sparsity_grad(w.sparsity, s.sigma);
                }
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
