//! Twin of `glsl/surface_train.comp`: the stage-2 (αSurf) training pass, forward and backward fused
//! per ray (method.md §3.2–3.4). One rayon task per ray; gradients scatter with CAS float atomics.
//!
//! Forward: the walk of `surface_fwd` (same DDA, per-cell hits, compositing), recording the ≤ a
//! composited hits (a ≤ [`SURF_MAX_HITS`]). Backward, per ray, over the recorded hits:
//! - colour: C = Σ w_j c_j + T_J·1; with S_J = 1 and S_j = α̃_j c_j + (1 − α̃_j) S_{j+1} (the colour
//!   seen from hit j on), ∂C/∂α̃_j = T_j (c_j − S_{j+1}): no division by 1 − α̃.
//! - entropy LH = −Σ p_j ln p_j, p = w/W: ∂LH/∂w_j = −(ln p_j + LH)/W (0 where w_j = 0), carried
//!   to the α̃ by the same recurrence as a colour channel without background ("gradient to α̃ only").
//! - Lc = Σ_j |t_j − t_mode| over the composited hits, t in scene units, t_mode the depth of the
//!   largest weight of the hit's structure (the whole ray unless the truncation count restarts):
//!   ∂/∂t_j = ±λc, to the hit depth.
//! - α̃ = γ_j·(1 − e^{−max(σα, 0)}) ⇒ ∂α̃/∂σα = γ_j e^{−σα} (σα > 0); colour c = max(0, raw).
//! - δ through the hit position: ∂s/∂δ_i = −w_i(p)/f′(s), f′(s) = ∇δ(p)·d; ∂L/∂s collects the
//!   spatial derivatives along d of σα and raw colour at p, and Lc. Hits with
//!   |f′| ≤ FPRIME_GUARD·(max δ − min δ over the cell) give δ no gradient and are counted.
//!
//! Scatter: the per-corner gradients of consecutive hits in one cell are summed (in reverse hit
//! order, as the kernel's reverse recurrence visits them) and added with one atomic per corner,
//! parameter and non-zero sum when the cell changes (SH: 3 colour sums per corner, times Y_k).
//!
//! Each loss term is a per-ray sum; the caller's weights (`grad_scale` for the squared error,
//! `lambda_h`, `lambda_c`) carry the batch normalisation.

use super::surface_fwd::{validate_blocks, validate_inputs};
use crate::abi::consts::TOUCH_SURFACE;
use crate::abi::surface_grid::SurfaceGridRef;
use crate::abi::train::SurfaceLoss;
use crate::math::atomic;
use crate::math::dda::ray_unit;
use crate::math::sh::sh_basis;
use crate::math::step::touch_mask;
use crate::math::surface::SurfaceParams;
use crate::math::surface::{
    surf_alpha, surf_cell_hits, surf_gamma, surf_ray, surf_restart, FaceSigns, Truncation,
    TruncationCount, SURF_MAX_LEVELS,
};
use crate::math::surface_blocks::SkipRef;
use crate::math::surface_walk::CellWalk;
use crate::math::trilerp::trilerp_weights;
use anyhow::{ensure, Result};
use rayon::prelude::*;
use std::sync::atomic::AtomicU32;

pub use crate::abi::buffers::{RayLoss, TrainCounts};
pub use crate::abi::consts::{FPRIME_GUARD, SURF_MAX_HITS, SURF_PASS_MIN_T};

/// Gradient outputs of one training pass, and the per-vertex touched flags.
pub struct SurfaceGrads<'a> {
    pub delta: &'a mut [f32],
    pub opacity: &'a mut [f32],
    pub sh: &'a mut [f32],
    pub touched: &'a mut [u32],
    /// dL/dbg (a learned background), or `None` (fixed: not accumulated).
    pub background: Option<&'a mut [f32; 3]>,
}

/// One composited hit: its cell, corner links, level, and where the ray meets it.
#[derive(Clone, Copy, Debug, Default)]
pub struct Hit {
    /// Grid cell (lower corner).
    pub cell: [i32; 3],
    pub lk: [i32; 8],
    /// Corner δ values (paper order).
    pub c: [f32; 8],
    /// Entry point of the cell's piece (local coordinates) and its t.
    pub q0: [f32; 3],
    pub t0: f32,
    /// Distance from the entry point to the hit, and the piece's length (voxels).
    pub s: f32,
    pub len: f32,
    /// Which level.
    pub level: u32,
    /// Its truncation count k (γ_a(k)).
    pub count: u32,
}

/// A ray's forward result: recorded hits, colour before the background, final transmittance.
#[derive(Clone, Copy, Debug)]
pub struct Trace {
    pub hits: [Hit; SURF_MAX_HITS],
    pub n: usize,
    /// Unit grid-space direction.
    pub dn: [f32; 3],
    /// 1/|rd∘scale|: voxels → scene units along the ray.
    pub inv_len: f32,
}

/// Hit position in its cell.
pub fn hit_point(h: &Hit, dn: [f32; 3]) -> [f32; 3] {
    std::array::from_fn(|k| (h.q0[k] + h.s * dn[k]).clamp(0.0, 1.0))
}

/// The forward walk of one ray (the kernel's first loop): the composited hits in order, with the
/// counters; the same stopping rules as `surface_fwd`. With `blocks` (the `surface_blocks` masks of
/// the current δ), cells of mask-0 blocks are skipped as in `surface_fwd` (exact).
pub fn trace_ray(
    g: &SurfaceGridRef,
    ro: [f32; 3],
    rd: [f32; 3],
    p: &SurfaceParams,
    blocks: Option<SkipRef>,
    cnt: &mut TrainCounts,
) -> Trace {
    let levels = &p.levels[..p.levels.len().min(SURF_MAX_LEVELS)];
    let (og, dn) = surf_ray(ro, rd, p.scale, p.offset);
    let dg: [f32; 3] = std::array::from_fn(|i| rd[i] * p.scale[i]);
    let len = (dg[0] * dg[0] + dg[1] * dg[1] + dg[2] * dg[2]).sqrt();
    let mut tr = Trace {
        hits: [Hit::default(); SURF_MAX_HITS],
        n: 0,
        dn,
        inv_len: if len > 0.0 { 1.0 / len } else { 0.0 },
    };
    let mut t_acc = 1.0f32;
    // The truncation count: the record index, or per structure the hits since the ray entered
    // level 0.
    let mut k = 0u32;
    let Truncation { a, count } = p.truncation;
    let mut walk = CellWalk::new(g, og, dn, levels, blocks);
    let mut face = FaceSigns::default();
    'walk: for cell in walk.by_ref() {
        let (piece, l, c, q0, lk) = (cell.piece, cell.piece.cell, cell.c, cell.q0, cell.lk);
        let len = piece.t1 - piece.t0;
        let before = face.before(piece.t0);
        let hits = surf_cell_hits(&c, cell.cc, q0, cell.q1, len, levels, cell.mask, before);
        face = FaceSigns {
            t: piece.t1,
            ..hits.exit
        };
        let mut outer = hits.outer;
        // The kernel's cell list holds its SURF_MAX_HITS first hits (more are reached only when
        // counting per structure passes truncated hits over; they are dropped).
        for (&s, &lv) in hits
            .as_slice()
            .iter()
            .zip(hits.levels())
            .take(SURF_MAX_HITS)
        {
            let j = tr.n;
            surf_restart(count, s, &mut outer, &mut k);
            if k as f32 >= a || j >= SURF_MAX_HITS {
                cnt.cut += 1;
                if count == TruncationCount::Structure
                    && j < SURF_MAX_HITS
                    && t_acc >= SURF_PASS_MIN_T
                {
                    continue;
                }
                break 'walk;
            }
            let h = Hit {
                cell: l,
                lk,
                c,
                q0,
                t0: piece.t0,
                s,
                len: piece.t1 - piece.t0,
                level: lv,
                count: k,
            };
            let wt = trilerp_weights(hit_point(&h, dn));
            let mut sa = 0.0f32;
            for i in 0..8 {
                sa += wt[i] * g.opacity[lk[i] as usize];
            }
            let at = surf_alpha(sa) * surf_gamma(a, k);
            tr.hits[j] = h;
            tr.n += 1;
            k += 1;
            cnt.hits += 1;
            t_acc *= 1.0 - at;
            if t_acc < p.stop_thresh {
                break 'walk;
            }
        }
    }
    let w = walk.counts;
    (cnt.cells, cnt.solves, cnt.culled, cnt.blocks_skipped) =
        (w.cells, w.solves, w.culled, w.blocks_skipped);
    tr
}

/// Per-hit shading quantities of the backward pass.
struct Shade {
    wt: [f32; 8],
    /// ∂w_i/∂s.
    dwds: [f32; 8],
    sa: f32,
    /// e^{−max(σα, 0)} = 1 − α.
    e: f32,
    gamma: f32,
    at: f32,
    raw: [f32; 3],
}

fn shade(g: &SurfaceGridRef, h: &Hit, dn: [f32; 3], y: &[f32; 9], a: f32) -> Shade {
    let p = hit_point(h, dn);
    let wt = trilerp_weights(p);
    let q = [1.0 - p[0], 1.0 - p[1], 1.0 - p[2]];
    let dwds = std::array::from_fn(|i| {
        let (bx, by, bz) = (i >> 2 & 1, i >> 1 & 1, i & 1);
        let fx = if bx == 1 { p[0] } else { q[0] };
        let fy = if by == 1 { p[1] } else { q[1] };
        let fz = if bz == 1 { p[2] } else { q[2] };
        let sx = if bx == 1 { 1.0 } else { -1.0 };
        let sy = if by == 1 { 1.0 } else { -1.0 };
        let sz = if bz == 1 { 1.0 } else { -1.0 };
        sx * fy * fz * dn[0] + fx * sy * fz * dn[1] + fx * fy * sz * dn[2]
    });
    let mut sa = 0.0f32;
    for i in 0..8 {
        sa += wt[i] * g.opacity[h.lk[i] as usize];
    }
    let e = (-sa.max(0.0)).exp();
    let gamma = surf_gamma(a, h.count);
    let at = surf_alpha(sa) * gamma;
    let mut raw = [0.5f32; 3];
    for i in 0..8 {
        let row = &g.sh[h.lk[i] as usize * 27..h.lk[i] as usize * 27 + 27];
        for ch in 0..3 {
            let mut v = 0.0f32;
            for k in 0..9 {
                v += y[k] * row[ch * 9 + k];
            }
            raw[ch] += wt[i] * v;
        }
    }
    Shade {
        wt,
        dwds,
        sa,
        e,
        gamma,
        at,
        raw,
    }
}

/// Twin of `surface_train.comp`: per-ray losses and the summed counters; dL/dδ, dL/dσα and
/// dL/dSH are added into `grads` and every vertex receiving a gradient is flagged; dL/dbg =
/// Σ_rays dL/dC·T is added when `grads.background` is given. `blocks`: the
/// `surface_blocks` masks of the current δ (the kernel always skips with them; `None` walks every
/// cell, with the same result).
pub fn train(
    g: &SurfaceGridRef,
    batch: TrainInput,
    p: &SurfaceParams,
    loss: &SurfaceLoss,
    blocks: Option<SkipRef>,
    grads: SurfaceGrads,
) -> Result<(Vec<RayLoss>, TrainCounts)> {
    let TrainInput {
        rays,
        targets,
        weights,
    } = batch;
    validate_inputs(g, rays, p)?;
    validate_blocks(g, blocks)?;
    ensure!(
        p.truncation.a <= SURF_MAX_HITS as f32,
        "truncation parameter a = {} exceeds the {SURF_MAX_HITS} hits a ray records",
        p.truncation.a
    );
    ensure!(
        targets.len() * 2 == rays.len(),
        "{} targets for {} rays",
        targets.len() / 3,
        rays.len() / 6
    );
    ensure!(
        weights.is_none_or(|w| w.len() * 6 == rays.len()),
        "{} weights for {} rays",
        weights.map_or(0, |w| w.len()),
        rays.len() / 6
    );
    let rows = g.delta.len();
    ensure!(
        grads.delta.len() == rows
            && grads.opacity.len() == rows
            && grads.sh.len() == 27 * rows
            && grads.touched.len() == rows,
        "gradient arrays do not match the {rows} vertex rows"
    );
    let out = Scatter {
        delta: atomic::as_atomic(grads.delta),
        opacity: atomic::as_atomic(grads.opacity),
        sh: atomic::as_atomic(grads.sh),
        touched: atomic::as_atomic_u32(grads.touched),
    };
    let res: Vec<(RayLoss, [f32; 3], TrainCounts)> = rays
        .par_chunks_exact(6)
        .zip(targets.par_chunks_exact(3))
        .enumerate()
        .map(|(i, (r, t))| {
            // The ray's loss terms are ω times the unweighted ones (the kernel's order: each
            // weight times ω, then the reported terms times ω).
            let omega = weights.map_or(1.0, |w| w[i]);
            let weighted = SurfaceLoss {
                grad_scale: loss.grad_scale * omega,
                lambda_h: loss.lambda_h * omega,
                lambda_c: loss.lambda_c * omega,
            };
            let (mut rl, d_bg, counts) = train_ray(
                g,
                [r[0], r[1], r[2]],
                [r[3], r[4], r[5]],
                [t[0], t[1], t[2]],
                p,
                &weighted,
                blocks,
                &out,
            );
            rl.sq_err *= omega;
            rl.entropy *= omega;
            rl.consistency *= omega;
            (rl, d_bg, counts)
        })
        .collect();
    if let Some(gb) = grads.background {
        for o in &res {
            for ch in 0..3 {
                gb[ch] += o.1[ch];
            }
        }
    }
    let counts = res
        .iter()
        .fold(TrainCounts::default(), |a, (_, _, c)| a + *c);
    Ok((res.into_iter().map(|o| o.0).collect(), counts))
}

/// A training batch: rays (6 floats each), their targets (3 floats each) and, for a focused
/// batch, each ray's importance weight ω (`abi::rays::Focus`; `None`: ω = 1).
#[derive(Clone, Copy, Debug)]
pub struct TrainInput<'a> {
    pub rays: &'a [f32],
    pub targets: &'a [f32],
    pub weights: Option<&'a [f32]>,
}

/// The gradient arrays as atomics.
struct Scatter<'a> {
    delta: &'a [AtomicU32],
    opacity: &'a [AtomicU32],
    sh: &'a [AtomicU32],
    touched: &'a [AtomicU32],
}

/// Per-hit gradients: ∂L/∂α̃ (before the chain to σα), ∂L/∂raw colour, and ∂L/∂t from Lc.
pub struct HitGrads {
    pub d_at: f32,
    pub d_raw: [f32; 3],
    pub d_t: f32,
}

/// The loss of one traced ray and the per-hit gradients with respect to α̃_j, raw colour and
/// depth (the part of the backward pass that does not touch the grid), and dL/dbg = dL/dC·T.
fn ray_backward(
    tr: &Trace,
    sh: &[Shade],
    target: [f32; 3],
    loss: &SurfaceLoss,
    bg: [f32; 3],
) -> (RayLoss, [HitGrads; SURF_MAX_HITS], [f32; 3]) {
    let n = tr.n;
    let mut t = [1.0f32; SURF_MAX_HITS + 1];
    let mut w = [0.0f32; SURF_MAX_HITS];
    let mut color = [0.0f32; 3];
    for j in 0..n {
        w[j] = t[j] * sh[j].at;
        for ch in 0..3 {
            color[ch] += w[j] * sh[j].raw[ch].max(0.0);
        }
        t[j + 1] = t[j] * (1.0 - sh[j].at);
    }
    let total: [f32; 3] = std::array::from_fn(|ch| color[ch] + t[n] * bg[ch]);
    let diff: [f32; 3] = std::array::from_fn(|ch| total[ch] - target[ch]);
    let mut out = RayLoss {
        sq_err: diff[0] * diff[0] + diff[1] * diff[1] + diff[2] * diff[2],
        hits: n as u32,
        ..Default::default()
    };
    let d_c = diff.map(|d| loss.grad_scale * d);
    let d_bg = d_c.map(|d| d * t[n]);

    // Entropy of the normalised weights and ∂(λH·LH)/∂w_j.
    let mut e = [0.0f32; SURF_MAX_HITS];
    let wsum: f32 = w[..n].iter().sum();
    if loss.lambda_h != 0.0 && wsum > 1e-8 {
        let mut h = 0.0f32;
        for &wj in &w[..n] {
            if wj > 0.0 {
                let pj = wj / wsum;
                h -= pj * pj.ln();
            }
        }
        out.entropy = h;
        for j in 0..n {
            if w[j] > 0.0 {
                e[j] = -loss.lambda_h * ((w[j] / wsum).ln() + h) / wsum;
            }
        }
    }
    // Lc per structure (the records from one whose truncation count is 0 to the next such: one
    // structure unless the count restarts): depths in scene units, the structure's mode = its
    // first largest weight.
    let mut d_t = [0.0f32; SURF_MAX_HITS];
    if loss.lambda_c != 0.0 && n > 1 {
        let mut first = [0usize; SURF_MAX_HITS];
        for j in 1..n {
            first[j] = if tr.hits[j].count == 0 {
                j
            } else {
                first[j - 1]
            };
        }
        let mode = |j: usize| {
            (first[j]..n)
                .filter(|&i| first[i] == first[j])
                .fold(first[j], |m, i| if w[i] > w[m] { i } else { m })
        };
        let depth = |j: usize| (tr.hits[j].t0 + tr.hits[j].s) * tr.inv_len;
        for j in 0..n {
            let m = mode(j);
            if j == m {
                continue;
            }
            let dj = depth(j) - depth(m);
            out.consistency += dj.abs();
            let sg = if dj > 0.0 {
                1.0
            } else if dj < 0.0 {
                -1.0
            } else {
                0.0
            };
            d_t[j] += loss.lambda_c * sg;
            d_t[m] -= loss.lambda_c * sg;
        }
    }
    // Reverse pass: colour and entropy seen from behind each hit (behind the last: the
    // background).
    let mut grads: [HitGrads; SURF_MAX_HITS] = std::array::from_fn(|_| HitGrads {
        d_at: 0.0,
        d_raw: [0.0; 3],
        d_t: 0.0,
    });
    let mut s_c = bg;
    let mut s_e = 0.0f32;
    for j in (0..n).rev() {
        let at = sh[j].at;
        let c = sh[j].raw.map(|r| r.max(0.0));
        let mut d_at = t[j] * (e[j] - s_e);
        for ch in 0..3 {
            d_at += d_c[ch] * t[j] * (c[ch] - s_c[ch]);
        }
        grads[j] = HitGrads {
            d_at,
            d_raw: std::array::from_fn(|ch| {
                if sh[j].raw[ch] > 0.0 {
                    d_c[ch] * w[j]
                } else {
                    0.0
                }
            }),
            d_t: d_t[j],
        };
        for ch in 0..3 {
            s_c[ch] = at * c[ch] + (1.0 - at) * s_c[ch];
        }
        s_e = at * e[j] + (1.0 - at) * s_e;
    }
    (out, grads, d_bg)
}

#[allow(clippy::too_many_arguments)] // the kernel's per-ray inputs, one argument each
fn train_ray(
    g: &SurfaceGridRef,
    ro: [f32; 3],
    rd: [f32; 3],
    target: [f32; 3],
    p: &SurfaceParams,
    loss: &SurfaceLoss,
    blocks: Option<SkipRef>,
    out: &Scatter,
) -> (RayLoss, [f32; 3], TrainCounts) {
    let mut cnt = TrainCounts::default();
    let tr = trace_ray(g, ro, rd, p, blocks, &mut cnt);
    let y = sh_basis(ray_unit(rd));
    let shades: Vec<Shade> = (0..tr.n)
        .map(|j| shade(g, &tr.hits[j], tr.dn, &y, p.truncation.a))
        .collect();
    let (rl, hg, d_bg) = ray_backward(&tr, &shades, target, loss, p.background);
    // Per-corner sums over consecutive hits in one cell, in reverse hit order (the kernel scatters
    // inside its reverse recurrence), flushed when the cell changes.
    let mut acc = CellAcc::default();
    for j in (0..tr.n).rev() {
        let (h, s, gr) = (&tr.hits[j], &shades[j], &hg[j]);
        let d_sa = if s.sa > 0.0 {
            gr.d_at * s.gamma * s.e
        } else {
            0.0
        };
        // ∂L/∂s: opacity and colour move with the hit point, and the depth (Lc).
        let mut dsa_ds = 0.0f32;
        let mut f1 = 0.0f32;
        let mut draw_ds = [0.0f32; 3];
        for i in 0..8 {
            let row = h.lk[i] as usize;
            dsa_ds += s.dwds[i] * g.opacity[row];
            f1 += s.dwds[i] * h.c[i];
            for ch in 0..3 {
                let mut v = 0.0f32;
                for k in 0..9 {
                    v += y[k] * g.sh[row * 27 + ch * 9 + k];
                }
                draw_ds[ch] += s.dwds[i] * v;
            }
        }
        let mut dl_ds = d_sa * dsa_ds + gr.d_t * tr.inv_len;
        for ch in 0..3 {
            dl_ds += gr.d_raw[ch] * draw_ds[ch];
        }
        let cmin = h.c.iter().copied().fold(f32::INFINITY, f32::min);
        let cmax = h.c.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        let guarded = f1.abs() <= FPRIME_GUARD * (cmax - cmin);
        if guarded {
            cnt.guarded += 1;
        }
        let d_delta_scale = if guarded || dl_ds == 0.0 {
            0.0
        } else {
            -dl_ds / f1
        };
        if acc.cell != Some(h.cell) {
            cnt.atomic_adds += acc.flush(out, &y);
            acc.cell = Some(h.cell);
            acc.lk = h.lk;
        }
        for i in 0..8 {
            let wi = s.wt[i];
            let (td, ta) = (wi * d_delta_scale, wi * d_sa);
            acc.delta[i] += td;
            acc.opacity[i] += ta;
            acc.nz_d |= u32::from(td != 0.0) << i;
            acc.nz_a |= u32::from(ta != 0.0) << i;
            for ch in 0..3 {
                let tc = wi * gr.d_raw[ch];
                acc.color[i][ch] += tc;
                acc.nz_c |= u32::from(tc != 0.0) << (3 * i + ch);
            }
        }
    }
    cnt.atomic_adds += acc.flush(out, &y);
    (rl, d_bg, cnt)
}

/// Per-corner gradient sums of the current cell (SH as 3 colour sums: Y is constant along a ray).
#[derive(Default)]
struct CellAcc {
    cell: Option<[i32; 3]>,
    lk: [i32; 8],
    delta: [f32; 8],
    opacity: [f32; 8],
    color: [[f32; 3]; 8],
    /// Bit i (δ, σα) or 3i + ch (colour): corner i received a non-zero term. The adds follow these
    /// single products, not the sums being zero: a sum's exact zero could depend on whether a GPU
    /// compiler fused its additions.
    nz_d: u32,
    nz_a: u32,
    nz_c: u32,
}

impl CellAcc {
    /// One atomic add per corner and parameter that received a non-zero term; corners that get one
    /// are touched. Clears the sums and masks and returns the number of adds.
    fn flush(&mut self, out: &Scatter, y: &[f32; 9]) -> u32 {
        if self.cell.is_none() {
            return 0;
        }
        let mut adds = 0;
        for i in 0..8 {
            let (dd, dsa, dcol) = (self.delta[i], self.opacity[i], self.color[i]);
            (self.delta[i], self.opacity[i], self.color[i]) = (0.0, 0.0, [0.0; 3]);
            let (bd, ba) = ((self.nz_d >> i) & 1 != 0, (self.nz_a >> i) & 1 != 0);
            let bc = (self.nz_c >> (3 * i)) & 7;
            if !bd && !ba && bc == 0 {
                continue;
            }
            let row = self.lk[i] as usize;
            touch_mask(out.touched, row, TOUCH_SURFACE);
            if bd {
                atomic::add(&out.delta[row], dd);
                adds += 1;
            }
            if ba {
                atomic::add(&out.opacity[row], dsa);
                adds += 1;
            }
            for ch in 0..3 {
                if (bc >> ch) & 1 == 0 {
                    continue;
                }
                for k in 0..9 {
                    atomic::add(&out.sh[row * 27 + ch * 9 + k], dcol[ch] * y[k]);
                }
                adds += 9;
            }
        }
        (self.nz_d, self.nz_a, self.nz_c) = (0, 0, 0);
        adds
    }
}
