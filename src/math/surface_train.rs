//! The per-ray pieces of stage-2 training that read no buffer (method.md §3.2–3.4): the twin of
//! `glsl/lib/surface_train.glsl` (same operations in the same order). The record of a composited
//! hit and its shading from one corner, the f′ guard, compositing from the records, the entropy
//! LH and depth consistency Lc with their gradients, one step of the reverse recurrence, the
//! gradients of a hit's σα and δ, and the per-corner gradient sums of a cell.

use super::surface::surf_cell_range;

pub use crate::abi::consts::{FPRIME_GUARD, SURF_MAX_HITS};

/// What the backward pass needs of a composited hit.
#[derive(Clone, Copy, Debug, Default)]
pub struct HitRec {
    pub cell: [i32; 3],
    /// Local hit point.
    pub p: [f32; 3],
    /// t0 + s (voxels).
    pub depth: f32,
    /// σα.
    pub sa: f32,
    /// α̃.
    pub at: f32,
    /// γ_a(k), k the hit's truncation count.
    pub gam: f32,
    /// Its structure along the ray (0 unless the count restarts).
    pub sid: u32,
    /// Raw colour.
    pub raw: [f32; 3],
    /// ∂raw/∂s.
    pub draw: [f32; 3],
    /// ∂σα/∂s.
    pub dsa: f32,
    /// f′(s).
    pub f1: f32,
    /// The f′ guard drops the δ gradient.
    pub guard: bool,
}

/// Adds corner i's share to a hit's shading and its derivatives along the ray: trilinear weight
/// `w`, its derivative `dw` along the ray, the corner's raw σα `op`, δ `c` and SH coefficients
/// `shv` (27), SH basis `y`. `h.raw` starts at 0.5, `h.draw`, `h.dsa` and `h.f1` at 0.
pub fn surf_shade_corner(
    h: &mut HitRec,
    w: f32,
    dw: f32,
    op: f32,
    c: f32,
    y: &[f32; 9],
    shv: &[f32],
) {
    h.dsa += dw * op;
    h.f1 += dw * c;
    for ch in 0..3 {
        let mut v = 0.0f32;
        for k in 0..9 {
            v += y[k] * shv[ch * 9 + k];
        }
        h.raw[ch] += w * v;
        h.draw[ch] += dw * v;
    }
}

/// The f′ guard: |f′(s)| ≤ FPRIME_GUARD·(max − min of the cell's δ `c`) gives δ no gradient.
pub fn surf_guard(f1: f32, c: &[f32; 8]) -> bool {
    let (cmin, cmax) = surf_cell_range(c);
    f1.abs() <= FPRIME_GUARD * (cmax - cmin)
}

/// Compositing from the records: the transmittance before each slot (the slots past the records
/// copy the last, so `[SURF_MAX_HITS]` is the ray's final one), the weights (0 past the records)
/// and the colour before the background.
pub fn surf_composite(
    rec: &[HitRec],
) -> ([f32; SURF_MAX_HITS + 1], [f32; SURF_MAX_HITS], [f32; 3]) {
    let mut tr = [1.0f32; SURF_MAX_HITS + 1];
    let mut wj = [0.0f32; SURF_MAX_HITS];
    let mut color = [0.0f32; 3];
    for k in 0..SURF_MAX_HITS {
        tr[k + 1] = tr[k];
        let Some(h) = rec.get(k) else { continue };
        wj[k] = tr[k] * h.at;
        for ch in 0..3 {
            color[ch] += wj[k] * h.raw[ch].max(0.0);
        }
        tr[k + 1] = tr[k] * (1.0 - h.at);
    }
    (tr, wj, color)
}

/// Entropy LH of the first `nh` normalised weights `wj` (0 when `lambda_h` = 0 or Σw ≤ 1e-8), and
/// e_j = ∂(λH·LH)/∂w_j (0 where w_j = 0 or LH is not formed).
pub fn surf_entropy(
    wj: &[f32; SURF_MAX_HITS],
    nh: usize,
    lambda_h: f32,
) -> (f32, [f32; SURF_MAX_HITS]) {
    let mut e = [0.0f32; SURF_MAX_HITS];
    let mut wsum = 0.0f32;
    for &w in &wj[..nh] {
        wsum += w;
    }
    let mut h = 0.0f32;
    if lambda_h == 0.0 || !(wsum > 1e-8) {
        return (h, e);
    }
    for &w in &wj[..nh] {
        if w > 0.0 {
            let pk = w / wsum;
            h -= pk * pk.ln();
        }
    }
    for k in 0..nh {
        if wj[k] > 0.0 {
            e[k] = -lambda_h * ((wj[k] / wsum).ln() + h) / wsum;
        }
    }
    (h, e)
}

/// Lc per structure (one, unless the truncation count restarts) over the records with weights
/// `wj`: Σ |t_j − t_mode| with depths in scene units (× `inv_len`), the structure's mode = its
/// first largest weight (0 when `lambda_c` = 0 or there are fewer than two records), and
/// d_t_j = ∂(λc·Lc)/∂t_j; ∂/∂t_mode is summed apart per structure. Structures are runs of records
/// with one `sid`: each pass is one sweep over the records.
pub fn surf_consistency(
    rec: &[HitRec],
    wj: &[f32; SURF_MAX_HITS],
    lambda_c: f32,
    inv_len: f32,
) -> (f32, [f32; SURF_MAX_HITS]) {
    let nh = rec.len();
    let mut d_t = [0.0f32; SURF_MAX_HITS];
    let mut lc = 0.0f32;
    if lambda_c == 0.0 || nh <= 1 {
        return (lc, d_t);
    }
    let starts = |k: usize| k == 0 || rec[k].sid != rec[k - 1].sid;
    // Each slot's mode and the mode's depth: running forward over its run, then handed back from
    // the run's last slot.
    let mut mk = [0usize; SURF_MAX_HITS];
    let mut tmk = [0.0f32; SURF_MAX_HITS];
    let (mut m, mut wm, mut tm) = (0usize, -1.0f32, 0.0f32);
    for k in 0..nh {
        if starts(k) || wj[k] > wm {
            (m, wm, tm) = (k, wj[k], rec[k].depth);
        }
        (mk[k], tmk[k]) = (m, tm);
    }
    for k in (1..nh).rev() {
        if !starts(k) {
            (mk[k - 1], tmk[k - 1]) = (mk[k], tmk[k]);
        }
    }
    // The terms, and per run −Σ λ·sign over its other slots (left at each slot as the run's sum so
    // far, then handed back from the run's last slot to its mode).
    let mut acc = 0.0f32;
    let mut tot = [0.0f32; SURF_MAX_HITS];
    for k in 0..nh {
        if starts(k) {
            acc = 0.0;
        }
        if k != mk[k] {
            let tmode = tmk[k] * inv_len;
            let dk = rec[k].depth * inv_len - tmode;
            lc += dk.abs();
            let sg = if dk > 0.0 {
                1.0
            } else if dk < 0.0 {
                -1.0
            } else {
                0.0
            };
            d_t[k] = lambda_c * sg;
            acc -= lambda_c * sg;
        }
        tot[k] = acc;
    }
    for k in (1..nh).rev() {
        if !starts(k) {
            tot[k - 1] = tot[k];
        }
    }
    for k in 0..nh {
        if mk[k] == k {
            d_t[k] = tot[k];
        }
    }
    (lc, d_t)
}

/// One step of the reverse recurrence at hit `h` (transmittance before it `trk`, weight `wk`,
/// entropy gradient `ek`; dL/dC `d_c`): ∂L/∂α̃ and ∂L/∂raw (ReLU-gated); moves the colour `s_c`
/// and entropy `s_e` seen from behind the hit to those seen from before it.
pub fn surf_reverse_step(
    h: &HitRec,
    trk: f32,
    wk: f32,
    ek: f32,
    d_c: [f32; 3],
    s_c: &mut [f32; 3],
    s_e: &mut f32,
) -> (f32, [f32; 3]) {
    let at = h.at;
    let col = h.raw.map(|r| r.max(0.0));
    let mut d_at = trk * (ek - *s_e);
    for ch in 0..3 {
        d_at += d_c[ch] * trk * (col[ch] - s_c[ch]);
    }
    let d_raw = std::array::from_fn(|ch| if h.raw[ch] > 0.0 { d_c[ch] * wk } else { 0.0 });
    for ch in 0..3 {
        s_c[ch] = at * col[ch] + (1.0 - at) * s_c[ch];
    }
    *s_e = at * ek + (1.0 - at) * *s_e;
    (d_at, d_raw)
}

/// (∂L/∂σα, the δ scale) of hit `h`: ∂L/∂σα = ∂L/∂α̃·γ·e^{−σα} (σα > 0), and
/// ∂L/∂δ_i = w_i·(δ scale) = −w_i·(∂L/∂s)/f′(s), where ∂L/∂s collects opacity and colour moving
/// with the hit point and the depth gradient `dtk` (Lc; × `inv_len` to scene units); 0 where the
/// f′ guard holds or ∂L/∂s = 0.
pub fn surf_hit_grads(
    h: &HitRec,
    d_at: f32,
    d_raw: [f32; 3],
    dtk: f32,
    inv_len: f32,
) -> (f32, f32) {
    let sa = h.sa;
    let ex = (-sa.max(0.0)).exp();
    let g_sa = if sa > 0.0 { d_at * h.gam * ex } else { 0.0 };
    let mut dl_ds = g_sa * h.dsa + dtk * inv_len;
    for ch in 0..3 {
        dl_ds += d_raw[ch] * h.draw[ch];
    }
    let dds = if h.guard || dl_ds == 0.0 {
        0.0
    } else {
        -dl_ds / h.f1
    };
    (g_sa, dds)
}

/// Per-corner gradient sums of the hits of one cell (SH as 3 colour sums: Y is constant along a
/// ray) and which corners and parameters received a non-zero term.
#[derive(Clone, Copy, Debug, Default)]
pub struct CornerSums {
    pub d: [f32; 8],
    pub a: [f32; 8],
    pub c: [[f32; 3]; 8],
    /// Bit i (δ, σα) or 3i + ch (colour): corner i received a non-zero term. The adds follow these
    /// single products, not the sums being zero: a sum's exact zero could depend on whether a GPU
    /// compiler fused its additions.
    pub nz_d: u32,
    pub nz_a: u32,
    pub nz_c: u32,
}

/// Adds a hit's terms with trilinear weights `wt`: w_i·dds to δ, w_i·d_sa to σα, w_i·d_raw to the
/// colour sums.
pub fn surf_sums_add(s: &mut CornerSums, wt: &[f32; 8], dds: f32, d_sa: f32, d_raw: [f32; 3]) {
    for i in 0..8 {
        let (td, ta) = (wt[i] * dds, wt[i] * d_sa);
        s.d[i] += td;
        s.a[i] += ta;
        s.nz_d |= u32::from(td != 0.0) << i;
        s.nz_a |= u32::from(ta != 0.0) << i;
        for ch in 0..3 {
            let tc = wt[i] * d_raw[ch];
            s.c[i][ch] += tc;
            s.nz_c |= u32::from(tc != 0.0) << (3 * i + ch);
        }
    }
}
