//! Generated inputs of the cell cubic solver, shared by its parity row (`check::cubic_solve`) and
//! its stress suite (`bench::cubic`), and the f64 oracle's view of each case.
//!
//! Case classes ([`CaseClass`]) are generated so that the named property holds exactly in the f32
//! inputs where that is possible. [`OracleCase`] holds what the oracle (`math::cubic_oracle`) knows
//! about a case: its crossings, the near-tangent floor ([`FLOOR`]) and face ambiguity
//! ([`BOUNDARY_REL`]) that excuse a solver's disagreement.

use crate::cpu::cubic_solve::CubicCase;
use crate::math::cubic_oracle::{deriv64, eval64, oracle_coefs, oracle_solve, OracleCrossing};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// Near-tangent floor: a crossing counts when |f′(s)|·L ≥ FLOOR · max_i |δ_i − τ|. f32 resolves
/// the sign of f at a tangency only to ~1e-7 of the cell's range; a tangent pair with
/// |f′|·L ≈ 1e-3·range needs ~1e-8, so 1e-2 is the lowest floor an f32 solver can honour.
pub const FLOOR: f64 = 1e-2;
/// Lower edge of the informational band [FLOOR_BAND, FLOOR): misses and spurious crossings there
/// are reported (`band_missed`, `band_spurious`) but do not enter the rates.
pub const FLOOR_BAND: f64 = 1e-3;
/// An unmatched crossing is face-ambiguous when 0 < |f(face)| ≤ BOUNDARY_REL · max_i |δ_i − τ|
/// (f32 trilerps of δ − τ at a face carry a few ulps of the corner values).
pub const BOUNDARY_REL: f64 = 1e-6;

/// The stress classes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CaseClass {
    /// Random rays through cells with corners in [−1, 1], τ between the corner extremes.
    Random,
    /// One direction component exactly 0.
    Axis1,
    /// Two direction components exactly 0 (C3 = C2 = 0 exactly).
    Axis2,
    /// Grazing hits: a double root inside the segment, offset by ±10^U(−9,−1) of the cell's range
    /// (a quarter exactly tangent before rounding).
    Tangent,
    /// Triple roots inside the segment (before f32 rounding of the corners).
    Triple,
    /// The ray enters on a cell edge whose two corners equal τ: C0 − τ = 0 exactly.
    RootAt0,
    /// Half: axis-aligned rays leaving through an edge at the level (τ = 0), f(L) = 0 exactly;
    /// half: general rays with the root placed at L before rounding.
    RootAtL,
    /// Corner magnitudes spanning 1e-6 … 1e6 (per cell and per corner).
    WideRange,
    /// Corners τ + tiny noise (10^U(−7,−2) relative).
    NearConstant,
}

impl CaseClass {
    pub const ALL: [CaseClass; 9] = [
        CaseClass::Random,
        CaseClass::Axis1,
        CaseClass::Axis2,
        CaseClass::Tangent,
        CaseClass::Triple,
        CaseClass::RootAt0,
        CaseClass::RootAtL,
        CaseClass::WideRange,
        CaseClass::NearConstant,
    ];

    pub fn name(self) -> &'static str {
        match self {
            CaseClass::Random => "random",
            CaseClass::Axis1 => "axis1",
            CaseClass::Axis2 => "axis2",
            CaseClass::Tangent => "tangent",
            CaseClass::Triple => "triple",
            CaseClass::RootAt0 => "root_at_0",
            CaseClass::RootAtL => "root_at_L",
            CaseClass::WideRange => "wide_range",
            CaseClass::NearConstant => "near_constant",
        }
    }
}

fn unit(v: [f64; 3]) -> [f64; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    [v[0] / n, v[1] / n, v[2] / n]
}

/// Uniform direction on the sphere (rejection from the cube).
fn rand_dir(rng: &mut Pcg64) -> [f64; 3] {
    loop {
        let v = [
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        ];
        let n2: f64 = v.iter().map(|x| x * x).sum();
        if n2 > 1e-4 && n2 <= 1.0 {
            return unit(v);
        }
    }
}

fn f32_dir(d: [f64; 3]) -> [f32; 3] {
    [d[0] as f32, d[1] as f32, d[2] as f32]
}

/// A random chord of the unit cube along `d`: entry point o′ (clamped to [0,1]³) and length L,
/// both rounded to f32. Retries until L ≥ 1e-3.
fn chord(rng: &mut Pcg64, d: [f32; 3]) -> ([f32; 3], f32) {
    loop {
        let p: [f64; 3] = [rng.random(), rng.random(), rng.random()];
        let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
        for k in 0..3 {
            let dk = d[k] as f64;
            if dk != 0.0 {
                let a = (0.0 - p[k]) / dk;
                let b = (1.0 - p[k]) / dk;
                t0 = t0.max(a.min(b));
                t1 = t1.min(a.max(b));
            }
        }
        let l = (t1 - t0) as f32;
        if l >= 1e-3 {
            let o = [0, 1, 2].map(|k| ((p[k] + t0 * d[k] as f64).clamp(0.0, 1.0)) as f32);
            return (o, l);
        }
    }
}

fn rand_corners(rng: &mut Pcg64, scale: f64) -> [f64; 8] {
    std::array::from_fn(|_| scale * rng.random_range(-1.0..1.0))
}

fn tau_between(rng: &mut Pcg64, c: &[f32; 8]) -> f32 {
    let lo = c.iter().cloned().fold(f32::INFINITY, f32::min);
    let hi = c.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
    let t: f32 = rng.random();
    (lo + t * (hi - lo)).clamp(lo, hi)
}

/// Cubic coefficients [C0..C3] (no τ) of corners `w` along the ray, in f64.
fn cubic_of(w: &[f64; 8], o: [f32; 3], d: [f32; 3]) -> [f64; 4] {
    let mut c = [0.0; 4];
    for (i, &wi) in w.iter().enumerate() {
        let mut e = [0.0f32; 8];
        e[i] = 1.0;
        let col = oracle_coefs(&e, o, d, 0.0);
        for k in 0..4 {
            c[k] += wi * col[k];
        }
    }
    c
}

/// Least-change corners: `base` plus the minimum-norm correction making the ray's cubic `target`.
fn fit_corners(base: &[f64; 8], o: [f32; 3], d: [f32; 3], target: [f64; 4]) -> Option<[f64; 8]> {
    let cols: Vec<[f64; 4]> = (0..8)
        .map(|i| {
            let mut e = [0.0f32; 8];
            e[i] = 1.0;
            oracle_coefs(&e, o, d, 0.0)
        })
        .collect();
    let cur = cubic_of(base, o, d);
    let mut r: [f64; 4] = std::array::from_fn(|k| target[k] - cur[k]);
    // (M Mᵀ) y = r by Gaussian elimination with partial pivoting.
    let mut g = [[0.0f64; 4]; 4];
    for (a, row) in g.iter_mut().enumerate() {
        for (b, v) in row.iter_mut().enumerate() {
            *v = cols.iter().map(|c| c[a] * c[b]).sum();
        }
    }
    for col in 0..4 {
        let piv = (col..4).max_by(|&a, &b| g[a][col].abs().total_cmp(&g[b][col].abs()))?;
        if g[piv][col].abs() < 1e-12 {
            return None;
        }
        g.swap(col, piv);
        r.swap(col, piv);
        for row in col + 1..4 {
            let f = g[row][col] / g[col][col];
            let pivot_row = g[col];
            for (v, p) in g[row].iter_mut().zip(pivot_row).skip(col) {
                *v -= f * p;
            }
            r[row] -= f * r[col];
        }
    }
    let mut y = [0.0f64; 4];
    for row in (0..4).rev() {
        let s: f64 = (row + 1..4).map(|k| g[row][k] * y[k]).sum();
        y[row] = (r[row] - s) / g[row][row];
    }
    Some(std::array::from_fn(|i| {
        base[i] + (0..4).map(|k| cols[i][k] * y[k]).sum::<f64>()
    }))
}

fn to_f32(w: &[f64; 8], tau: f32) -> [f32; 8] {
    std::array::from_fn(|i| (tau as f64 + w[i]) as f32)
}

/// One case of `class` (retries internally until the construction is well posed).
fn gen_case(class: CaseClass, rng: &mut Pcg64) -> CubicCase {
    loop {
        if let Some(c) = try_case(class, rng) {
            return c;
        }
    }
}

fn try_case(class: CaseClass, rng: &mut Pcg64) -> Option<CubicCase> {
    match class {
        CaseClass::Random | CaseClass::Axis1 | CaseClass::Axis2 => general_case(class, rng),
        CaseClass::Tangent | CaseClass::Triple => repeated_root_case(class, rng),
        CaseClass::RootAt0 => root_at_0_case(rng),
        CaseClass::RootAtL => root_at_l_case(rng),
        CaseClass::WideRange => wide_range_case(rng),
        CaseClass::NearConstant => near_constant_case(rng),
    }
}

/// A random, one-axis or two-axis ray (`Random`, `Axis1`, `Axis2`) through random corners.
fn general_case(class: CaseClass, rng: &mut Pcg64) -> Option<CubicCase> {
    let mut d = rand_dir(rng);
    if class == CaseClass::Axis1 {
        d[rng.random_range(0..3)] = 0.0;
        d = unit(d);
    } else if class == CaseClass::Axis2 {
        let k = rng.random_range(0..3);
        d = [0.0; 3];
        d[k] = if rng.random() { 1.0 } else { -1.0 };
    }
    let d = f32_dir(d);
    let (o, l) = chord(rng, d);
    let w = rand_corners(rng, 1.0);
    let corners = to_f32(&w, 0.0);
    let tau = tau_between(rng, &corners);
    Some(CubicCase {
        corners,
        o,
        d,
        l,
        tau,
    })
}

/// A double (`Tangent`, possibly nudged apart) or triple (`Triple`) root inside the segment.
fn repeated_root_case(class: CaseClass, rng: &mut Pcg64) -> Option<CubicCase> {
    let d = f32_dir(rand_dir(rng));
    let (o, l) = chord(rng, d);
    if l < 0.2 {
        return None;
    }
    let base = rand_corners(rng, 1.0);
    let cb = cubic_of(&base, o, d);
    let mx = cb.iter().fold(0.0f64, |m, c| m.max(c.abs()));
    let lf = l as f64;
    let r = rng.random_range(0.1..0.9) * lf;
    let target = if class == CaseClass::Tangent {
        // (s − r)²(α s + β) keeping C3 and C2 of the random cell.
        let alpha = cb[3];
        let beta = cb[2] + 2.0 * r * alpha;
        if alpha.abs() + beta.abs() < 0.05 * mx {
            return None;
        }
        let mut t = [beta * r * r, alpha * r * r - 2.0 * r * beta, cb[2], alpha];
        if rng.random_range(0..4) != 0 {
            let mag = t.iter().fold(0.0f64, |m, c| m.max(c.abs()));
            let eps = mag * 10f64.powf(rng.random_range(-9.0..-1.0));
            t[0] += if rng.random() { eps } else { -eps };
        }
        t
    } else {
        let alpha = cb[3];
        if alpha.abs() < 0.1 * mx || alpha.abs() < 1e-3 {
            return None;
        }
        [
            -alpha * r * r * r,
            3.0 * alpha * r * r,
            -3.0 * alpha * r,
            alpha,
        ]
    };
    let w = fit_corners(&base, o, d, target)?;
    if w.iter().any(|v| v.abs() > 50.0) {
        return None;
    }
    let tau: f32 = rng.random_range(-1.0..1.0);
    Some(CubicCase {
        corners: to_f32(&w, tau),
        o,
        d,
        l,
        tau,
    })
}

/// `RootAt0`: entry on a cell edge whose two corners equal τ.
fn root_at_0_case(rng: &mut Pcg64) -> Option<CubicCase> {
    // Entry on a cell edge along axis k; the other two coordinates fixed at 0/1.
    let k = rng.random_range(0..3);
    let fixed: [f32; 3] = [0, 1, 2].map(|j| {
        if j == k {
            0.0
        } else {
            rng.random_range(0..2) as f32
        }
    });
    let mut d = rand_dir(rng);
    for j in 0..3 {
        if j != k {
            // Point into the cell and away from grazing the faces.
            let a = d[j].abs().max(0.05);
            d[j] = if fixed[j] == 0.0 { a } else { -a };
        }
    }
    let d = f32_dir(unit(d));
    let mut o = fixed;
    o[k] = rng.random();
    // L: exit of the cube from o along d.
    let mut l = f64::INFINITY;
    for j in 0..3 {
        let dj = d[j] as f64;
        if dj > 0.0 {
            l = l.min((1.0 - o[j] as f64) / dj);
        } else if dj < 0.0 {
            l = l.min(-(o[j] as f64) / dj);
        }
    }
    let l = l as f32;
    if l < 1e-3 {
        return None;
    }
    let tau: f32 = rng.random_range(-1.0..1.0);
    let mut corners = to_f32(&rand_corners(rng, 1.0), tau);
    for (i, c) in corners.iter_mut().enumerate() {
        let bits = [(i >> 2) & 1, (i >> 1) & 1, i & 1];
        if (0..3).all(|j| j == k || bits[j] as f32 == fixed[j]) {
            *c = tau;
        }
    }
    Some(CubicCase {
        corners,
        o,
        d,
        l,
        tau,
    })
}

/// `RootAtL`: a root exactly or nearly at the exit, L.
fn root_at_l_case(rng: &mut Pcg64) -> Option<CubicCase> {
    if rng.random() {
        // Axis-aligned, τ = 0, leaving through an edge whose corners are 0.
        let k = rng.random_range(0..3);
        let plus: bool = rng.random();
        let mut d = [0.0f32; 3];
        d[k] = if plus { 1.0 } else { -1.0 };
        let e = (k + 1 + rng.random_range(0..2)) % 3; // edge coordinate (fixed 0/1)
        let ev = rng.random_range(0..2) as f32;
        let mut o = [0.0f32; 3];
        for (j, oj) in o.iter_mut().enumerate() {
            *oj = if j == k {
                if plus {
                    0.0
                } else {
                    1.0
                }
            } else if j == e {
                ev
            } else {
                rng.random()
            };
        }
        let exit_k = if plus { 1 } else { 0 };
        let mut corners = to_f32(&rand_corners(rng, 1.0), 0.0);
        for (i, c) in corners.iter_mut().enumerate() {
            let bits = [(i >> 2) & 1, (i >> 1) & 1, i & 1];
            if bits[k] == exit_k && bits[e] as f32 == ev {
                *c = 0.0;
            }
        }
        Some(CubicCase {
            corners,
            o,
            d,
            l: 1.0,
            tau: 0.0,
        })
    } else {
        let d = f32_dir(rand_dir(rng));
        let (o, l) = chord(rng, d);
        if l < 0.05 {
            return None;
        }
        let base = rand_corners(rng, 1.0);
        let cb = cubic_of(&base, o, d);
        let lf = l as f64;
        let t = [
            -(cb[1] * lf + cb[2] * lf * lf + cb[3] * lf * lf * lf),
            cb[1],
            cb[2],
            cb[3],
        ];
        let w = fit_corners(&base, o, d, t)?;
        let tau: f32 = rng.random_range(-1.0..1.0);
        Some(CubicCase {
            corners: to_f32(&w, tau),
            o,
            d,
            l,
            tau,
        })
    }
}

/// `WideRange`: corner magnitudes spanning 1e-6 … 1e6.
fn wide_range_case(rng: &mut Pcg64) -> Option<CubicCase> {
    let d = f32_dir(rand_dir(rng));
    let (o, l) = chord(rng, d);
    let corners: [f32; 8] = match rng.random_range(0..3) {
        0 => {
            let s = 10f64.powf(rng.random_range(-6.0..6.0));
            to_f32(&rand_corners(rng, s), 0.0)
        }
        _ => std::array::from_fn(|_| {
            let m = 10f64.powf(rng.random_range(-6.0..6.0));
            (if rng.random() { m } else { -m }) as f32
        }),
    };
    let tau = if rng.random() {
        tau_between(rng, &corners)
    } else {
        // A small level among large corners.
        let lo = corners.iter().cloned().fold(f32::INFINITY, f32::min);
        let hi = corners.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
        let m = 10f64.powf(rng.random_range(-6.0..0.0)) as f32;
        (if rng.random() { m } else { -m }).clamp(lo, hi)
    };
    Some(CubicCase {
        corners,
        o,
        d,
        l,
        tau,
    })
}

/// `NearConstant`: corners τ plus tiny noise.
fn near_constant_case(rng: &mut Pcg64) -> Option<CubicCase> {
    let d = f32_dir(rand_dir(rng));
    let (o, l) = chord(rng, d);
    let t = 10f64.powf(rng.random_range(-3.0..3.0));
    let tau = (if rng.random() { t } else { -t }) as f32;
    let eta = t * 10f64.powf(rng.random_range(-7.0..-2.0));
    let corners = to_f32(&rand_corners(rng, eta), tau);
    Some(CubicCase {
        corners,
        o,
        d,
        l,
        tau,
    })
}

/// `n` cases of `class`, deterministic in `seed`.
pub fn gen_cases(class: CaseClass, n: usize, seed: u64) -> Vec<CubicCase> {
    let mut rng =
        Pcg64::seed_from_u64(seed ^ (0x9e37_79b9_7f4a_7c15u64.wrapping_mul(class as u64 + 1)));
    (0..n).map(|_| gen_case(class, &mut rng)).collect()
}

/// What the oracle knows about one case, for scoring.
#[derive(Clone, Debug)]
pub struct OracleCase {
    pub coefs: [f64; 4],
    pub l: f64,
    /// max_i |δ_i − τ|.
    pub scale: f64,
    pub crossings: Vec<OracleCrossing>,
}

impl OracleCase {
    pub fn new(c: &CubicCase) -> Self {
        let coefs = oracle_coefs(&c.corners, c.o, c.d, c.tau);
        let l = c.l as f64;
        let scale = c
            .corners
            .iter()
            .fold(0.0f64, |m, &v| m.max((v as f64 - c.tau as f64).abs()));
        OracleCase {
            coefs,
            l,
            scale,
            crossings: oracle_solve(&coefs, l),
        }
    }

    /// |f′(s)|·L at or above the floor.
    pub fn significant_slope(&self, slope: f64) -> bool {
        slope * self.l >= FLOOR * self.scale
    }

    /// |f′(s)|·L in the informational band [FLOOR_BAND, FLOOR)·scale.
    pub fn in_band(&self, slope: f64) -> bool {
        slope * self.l >= FLOOR_BAND * self.scale && !self.significant_slope(slope)
    }

    /// The sign of f at the cell face nearest `s` is nonzero but below f32 resolution.
    pub fn face_ambiguous(&self, s: f64) -> bool {
        let face = if s < 0.5 * self.l { 0.0 } else { self.l };
        let fb = eval64(&self.coefs, face).abs();
        fb > 0.0 && fb <= BOUNDARY_REL * self.scale
    }

    /// A solver crossing at `s` that the oracle does not have is excused (near-tangent or
    /// face-ambiguous) rather than spurious.
    pub fn excused(&self, s: f64) -> bool {
        !self.significant_slope(deriv64(&self.coefs, s).abs()) || self.face_ambiguous(s)
    }
}
