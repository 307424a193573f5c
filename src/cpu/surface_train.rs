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
//! The pieces that read no buffer are `math::surface_train` (the twin of
//! `glsl/lib/surface_train.glsl`); this file holds the walk, the shading reads and the scatter.
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
    surf_alpha, surf_cell_hits, surf_gamma, surf_ray, FaceSigns, RayCount, SURF_MAX_LEVELS,
};
use crate::math::surface_blocks::SkipRef;
use crate::math::surface_train::{
    surf_composite, surf_consistency, surf_entropy, surf_guard, surf_hit_grads, surf_reverse_step,
    surf_shade_corner, surf_sums_add, CornerSums, HitRec,
};
use crate::math::surface_walk::CellWalk;
use crate::math::trilerp::{trilerp_dwds, trilerp_weights};
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
    let a = p.truncation.a;
    let mut rc = RayCount::new(p.truncation);
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
            rc.restart(s, &mut outer);
            if rc.truncated() || j >= SURF_MAX_HITS {
                cnt.cut += 1;
                if rc.passes_over() && j < SURF_MAX_HITS && t_acc >= SURF_PASS_MIN_T {
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
                count: rc.k,
            };
            let wt = trilerp_weights(hit_point(&h, dn));
            let mut sa = 0.0f32;
            for i in 0..8 {
                sa += wt[i] * g.opacity[lk[i] as usize];
            }
            let at = surf_alpha(sa) * surf_gamma(a, rc.k);
            tr.hits[j] = h;
            tr.n += 1;
            rc.k += 1;
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

/// Twin of the kernel's `hit_record`: the record of hit `h` (truncation parameter `a`; `sid` left 0
/// for the caller): σα, α̃, the shading and the derivatives along the ray `dn` the backward pass
/// needs (SH basis `y`), and the f′ guard verdict.
fn hit_record(g: &SurfaceGridRef, h: &Hit, dn: [f32; 3], y: &[f32; 9], a: f32) -> HitRec {
    let p = hit_point(h, dn);
    let wt = trilerp_weights(p);
    let dw = trilerp_dwds(p, dn);
    let mut sa = 0.0f32;
    for i in 0..8 {
        sa += wt[i] * g.opacity[h.lk[i] as usize];
    }
    let gam = surf_gamma(a, h.count);
    let mut hr = HitRec {
        cell: h.cell,
        p,
        depth: h.t0 + h.s,
        sa,
        at: surf_alpha(sa) * gam,
        gam,
        raw: [0.5; 3],
        ..Default::default()
    };
    for i in 0..8 {
        let row = h.lk[i] as usize;
        let shv = &g.sh[row * 27..row * 27 + 27];
        surf_shade_corner(&mut hr, wt[i], dw[i], g.opacity[row], h.c[i], y, shv);
    }
    hr.guard = surf_guard(hr.f1, &h.c);
    hr
}

/// The records of a traced ray's hits, each with its structure: a restarted truncation count
/// (count 0 after the first record) starts the next one.
fn hit_records(g: &SurfaceGridRef, tr: &Trace, y: &[f32; 9], a: f32) -> Vec<HitRec> {
    let mut sid = 0;
    (0..tr.n)
        .map(|j| {
            let h = &tr.hits[j];
            if h.count == 0 && j > 0 {
                sid += 1;
            }
            HitRec {
                sid,
                ..hit_record(g, h, tr.dn, y, a)
            }
        })
        .collect()
}

/// Twin of `surface_train.comp`: per-ray losses and the summed counters; dL/dδ, dL/dσα and
/// dL/dSH are added into `grads` and every vertex receiving a gradient is flagged; dL/dbg =
/// Σ_rays dL/dC·T·T_L is added when `grads.background` is given (the background's spheres,
/// `p.spheres`, are composited but not trained). `blocks`: the
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

/// A ray's loss terms from its records, and what the reverse pass reads of them.
struct RayTerms {
    loss: RayLoss,
    /// Transmittance before each slot (`[SURF_MAX_HITS]`: the final one) and the weights.
    tr: [f32; SURF_MAX_HITS + 1],
    wj: [f32; SURF_MAX_HITS],
    /// ∂(λH·LH)/∂w_j and ∂(λc·Lc)/∂t_j.
    e: [f32; SURF_MAX_HITS],
    d_t: [f32; SURF_MAX_HITS],
    /// dL/dC.
    d_c: [f32; 3],
}

/// Compositing from the records, the squared error and the regularisers' terms (the kernel's
/// `main` between the walk and the reverse pass).
fn ray_terms(
    rec: &[HitRec],
    inv_len: f32,
    target: [f32; 3],
    loss: &SurfaceLoss,
    bg: [f32; 3],
) -> RayTerms {
    let (tr, wj, color) = surf_composite(rec);
    let t_last = tr[SURF_MAX_HITS];
    let total: [f32; 3] = std::array::from_fn(|ch| color[ch] + t_last * bg[ch]);
    let diff: [f32; 3] = std::array::from_fn(|ch| total[ch] - target[ch]);
    let (entropy, e) = surf_entropy(&wj, rec.len(), loss.lambda_h);
    let (consistency, d_t) = surf_consistency(rec, &wj, loss.lambda_c, inv_len);
    RayTerms {
        loss: RayLoss {
            sq_err: diff[0] * diff[0] + diff[1] * diff[1] + diff[2] * diff[2],
            entropy,
            consistency,
            hits: rec.len() as u32,
        },
        tr,
        wj,
        e,
        d_t,
        d_c: diff.map(|d| loss.grad_scale * d),
    }
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
    let rec = hit_records(g, &tr, &y, p.truncation.a);
    let (behind, t_bg) = p.behind().behind(ro, rd);
    let t = ray_terms(&rec, tr.inv_len, target, loss, behind);
    // Reverse pass: colour and entropy seen from behind each hit (behind the last: the
    // background); per-corner sums over consecutive hits in one cell, flushed when the cell
    // changes.
    let mut s_c = behind;
    let mut s_e = 0.0f32;
    let mut acc = CellAcc::default();
    for (j, hk) in rec.iter().enumerate().rev() {
        let (d_at, d_raw) =
            surf_reverse_step(hk, t.tr[j], t.wj[j], t.e[j], t.d_c, &mut s_c, &mut s_e);
        let (d_sa, dds) = surf_hit_grads(hk, d_at, d_raw, t.d_t[j], tr.inv_len);
        if hk.guard {
            cnt.guarded += 1;
        }
        if acc.cell != Some(hk.cell) {
            cnt.atomic_adds += acc.flush(out, &y);
            acc.cell = Some(hk.cell);
            acc.lk = tr.hits[j].lk;
        }
        surf_sums_add(&mut acc.sums, &trilerp_weights(hk.p), dds, d_sa, d_raw);
    }
    cnt.atomic_adds += acc.flush(out, &y);
    let t_last = t.tr[SURF_MAX_HITS];
    (t.loss, t.d_c.map(|d| (d * t_last) * t_bg), cnt)
}

/// The current cell, its corner links and its per-corner gradient sums.
#[derive(Default)]
struct CellAcc {
    cell: Option<[i32; 3]>,
    lk: [i32; 8],
    sums: CornerSums,
}

impl CellAcc {
    /// One atomic add per corner and parameter that received a non-zero term; corners that get one
    /// are touched. Clears the sums and masks and returns the number of adds.
    fn flush(&mut self, out: &Scatter, y: &[f32; 9]) -> u32 {
        if self.cell.is_none() {
            return 0;
        }
        let s = &mut self.sums;
        let mut adds = 0;
        for i in 0..8 {
            let (dd, dsa, dcol) = (s.d[i], s.a[i], s.c[i]);
            (s.d[i], s.a[i], s.c[i]) = (0.0, 0.0, [0.0; 3]);
            let (bd, ba) = ((s.nz_d >> i) & 1 != 0, (s.nz_a >> i) & 1 != 0);
            let bc = (s.nz_c >> (3 * i)) & 7;
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
        (s.nz_d, s.nz_a, s.nz_c) = (0, 0, 0);
        adds
    }
}
