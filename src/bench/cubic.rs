//! `alphasurf bench cubic`: the numerical stress suite of the cell cubic solver (issue 2, item 7).
//!
//! Case classes ([`CaseClass`]) are generated so that the named property holds exactly in the f32
//! inputs where that is possible. Every solver is scored against the f64 oracle
//! (`math::cubic_oracle`): ours on the Vulkan device (`glsl/cubic_solve.comp`), ours on the CPU
//! (the twin), and the paper's f64 Vieta baseline (`math::vieta`).
//!
//! Scoring ([`score_case`]). An oracle crossing is *significant* when |f′(s)|·L ≥ [`FLOOR`]·scale,
//! scale = max_i |δ_i − τ|: its slope would change f by at least 1 % of the cell's range over the
//! segment. Misses and spurious crossings in the band [`FLOOR_BAND`]..[`FLOOR`] are reported apart. Crossings
//! are matched by direction and nearest s within [`MATCH_TOL`]. Unmatched significant oracle
//! crossings are *missed*; unmatched solver crossings where the oracle's |f′|·L is above the floor
//! are *spurious*. Unmatched crossings below the floor are *near-tangent* (excluded from the rates,
//! counted). Unmatched crossings next to a cell face where the oracle's |f(face)| is nonzero but
//! below f32 resolution ([`BOUNDARY_REL`]) are *face-ambiguous* (which cell owns them is decided by
//! a sign below rounding; excluded, counted). Missed rate = missed / significant oracle crossings;
//! spurious rate = spurious / cases; max |Δs| over matched significant crossings.

use crate::cpu::cubic_solve::{cubic_solve, cubic_solve_serial, CubicCase, CubicSolveOut};
use crate::gpu::Gpu;
use crate::math::cubic_oracle::{deriv64, eval64, oracle_coefs, oracle_solve, OracleCrossing};
use crate::math::vieta::vieta_crossings;
use anyhow::Result;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use rayon::prelude::*;
use std::time::Instant;

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
/// Largest |Δs| (voxel) at which a solver crossing can match an oracle crossing.
pub const MATCH_TOL: f64 = 1e-2;
/// Targets of issue 2: rates ≤ 1e-6, |Δs| ≤ 1e-4 voxel.
pub const RATE_TARGET: f64 = 1e-6;
pub const DS_TARGET: f64 = 1e-4;
/// Default cases per class.
pub const DEFAULT_CASES: usize = 200_000;

/// Arguments of `alphasurf bench cubic`.
#[derive(clap::Args, Debug, Clone)]
pub struct CubicBenchArgs {
    /// Cases per class.
    #[arg(long, default_value_t = DEFAULT_CASES)]
    pub cases: usize,
    /// Print one JSON object (per-class figures and an overall `pass`) as the last line.
    #[arg(long)]
    pub json: bool,
    /// Seed of the case generator.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

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
        CaseClass::Random | CaseClass::Axis1 | CaseClass::Axis2 => {
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
        CaseClass::Tangent | CaseClass::Triple => {
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
        CaseClass::RootAt0 => {
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
        CaseClass::RootAtL => {
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
        CaseClass::WideRange => {
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
        CaseClass::NearConstant => {
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
    }
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

/// Accuracy tallies of one solver over one class.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Score {
    pub cases: usize,
    pub significant: usize,
    pub matched: usize,
    pub missed: usize,
    pub spurious: usize,
    pub near_tangent: usize,
    pub band_missed: usize,
    pub band_spurious: usize,
    pub face_ambiguous: usize,
    pub max_ds: f64,
    pub non_finite: usize,
}

impl Score {
    fn add(&mut self, o: &Score) {
        self.cases += o.cases;
        self.significant += o.significant;
        self.matched += o.matched;
        self.missed += o.missed;
        self.spurious += o.spurious;
        self.near_tangent += o.near_tangent;
        self.band_missed += o.band_missed;
        self.band_spurious += o.band_spurious;
        self.face_ambiguous += o.face_ambiguous;
        self.max_ds = self.max_ds.max(o.max_ds);
        self.non_finite += o.non_finite;
    }

    pub fn missed_rate(&self) -> f64 {
        self.missed as f64 / self.significant.max(1) as f64
    }

    pub fn spurious_rate(&self) -> f64 {
        self.spurious as f64 / self.cases.max(1) as f64
    }

    /// The targets for our solver.
    pub fn meets_targets(&self) -> bool {
        self.non_finite == 0
            && self.missed_rate() <= RATE_TARGET
            && self.spurious_rate() <= RATE_TARGET
            && self.max_ds <= DS_TARGET
    }

    /// No less accurate than `base`: no more misses, spurious roots or non-finite values.
    pub fn not_worse_than(&self, base: &Score) -> bool {
        self.missed_rate() <= base.missed_rate()
            && self.spurious_rate() <= base.spurious_rate()
            && self.non_finite <= base.non_finite
    }
}

/// Score one case: solver crossings `got` as (s, rising), `non_finite` when the solver produced a
/// NaN/Inf for this case.
pub fn score_case(oc: &OracleCase, got: &[(f64, bool)], non_finite: bool) -> Score {
    let mut sc = Score {
        cases: 1,
        non_finite: non_finite as usize,
        ..Default::default()
    };
    let mut used = vec![false; got.len()];
    for x in &oc.crossings {
        let sig = oc.significant_slope(x.slope);
        sc.significant += sig as usize;
        let best = got
            .iter()
            .enumerate()
            .filter(|(j, g)| !used[*j] && g.1 == x.rising && (g.0 - x.s).abs() <= MATCH_TOL)
            .min_by(|a, b| (a.1 .0 - x.s).abs().total_cmp(&(b.1 .0 - x.s).abs()));
        match best {
            Some((j, g)) => {
                used[j] = true;
                if sig {
                    sc.matched += 1;
                    sc.max_ds = sc.max_ds.max((g.0 - x.s).abs());
                }
            }
            None if !sig => {
                sc.near_tangent += 1;
                sc.band_missed += oc.in_band(x.slope) as usize;
            }
            None if oc.face_ambiguous(x.s) => sc.face_ambiguous += 1,
            None => sc.missed += 1,
        }
    }
    for (j, g) in got.iter().enumerate() {
        if used[j] {
            continue;
        }
        if !g.0.is_finite() {
            sc.spurious += 1;
        } else if !oc.significant_slope(deriv64(&oc.coefs, g.0).abs()) {
            sc.near_tangent += 1;
            sc.band_spurious += oc.in_band(deriv64(&oc.coefs, g.0).abs()) as usize;
        } else if oc.face_ambiguous(g.0) {
            sc.face_ambiguous += 1;
        } else {
            sc.spurious += 1;
        }
    }
    sc
}

/// Our solver's crossings of case `i` as (s, rising), and whether any value is non-finite.
fn ours(out: &CubicSolveOut, i: usize) -> (Vec<(f64, bool)>, bool) {
    let x = out.get(i);
    let v: Vec<(f64, bool)> = x.iter().map(|(s, r)| (s as f64, r)).collect();
    let bad = out.count[i] > 3 || v.iter().any(|p| !p.0.is_finite());
    (v, bad)
}

/// Timed passes per measurement; the fastest counts (the machine is shared and noisy).
pub const REPEATS: usize = 3;

/// Run `f` REPEATS times; its last result and the fastest wall time (s).
fn best_of<T>(mut f: impl FnMut() -> T) -> (T, f64) {
    let mut best = f64::INFINITY;
    let mut out = None;
    for _ in 0..REPEATS {
        let t = Instant::now();
        out = Some(f());
        best = best.min(t.elapsed().as_secs_f64());
    }
    (out.expect("REPEATS > 0"), best)
}

/// Per-class result row.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ClassRow {
    pub class: &'static str,
    pub cases: usize,
    pub oracle_crossings: usize,
    pub gpu: Score,
    pub cpu: Score,
    pub baseline: Score,
    pub gpu_solves_per_s: f64,
    pub cpu_solves_per_s: f64,
    pub cpu1_solves_per_s: f64,
    pub baseline1_solves_per_s: f64,
    pub gpu_cpu_identical: usize,
    pub pass: bool,
}

/// Run the suite; prints the table (and the JSON line); returns `pass`.
pub fn run(gpu: &Gpu, args: &CubicBenchArgs) -> Result<bool> {
    anyhow::ensure!(args.cases > 0, "--cases must be positive");
    let n = args.cases;
    let t0 = Instant::now();
    let classes = CaseClass::ALL;
    let all: Vec<CubicCase> = classes
        .par_iter()
        .flat_map(|&c| gen_cases(c, n, args.seed))
        .collect();
    let ranges: Vec<std::ops::Range<usize>> =
        (0..classes.len()).map(|k| k * n..(k + 1) * n).collect();
    let oracle: Vec<OracleCase> = all.par_iter().map(OracleCase::new).collect();

    // Vulkan: a warm-up pass (lavapipe compiles at the first dispatch), then the timed pass with
    // one dispatch per class.
    let warm = n.min(1024);
    crate::check::cubic_solve::run_gpu(gpu, &all[..warm], std::slice::from_ref(&(0..warm)))?;
    let (gout, mut gns) = crate::check::cubic_solve::run_gpu(gpu, &all, &ranges)?;
    for _ in 1..REPEATS {
        let (again, ns) = crate::check::cubic_solve::run_gpu(gpu, &all, &ranges)?;
        anyhow::ensure!(again == gout, "the Vulkan kernel is not deterministic");
        for (a, b) in gns.iter_mut().zip(ns) {
            *a = a.min(b);
        }
    }

    let mut rows = Vec::new();
    for (k, class) in classes.iter().enumerate() {
        let r = ranges[k].clone();
        let cases = &all[r.clone()];
        let orc = &oracle[r.clone()];
        // CPU twin, rayon and one thread.
        let (cout, cpu_s) = best_of(|| cubic_solve(cases));
        let (cout1, cpu1_s) = best_of(|| cubic_solve_serial(cases));
        anyhow::ensure!(cout1 == cout, "serial and rayon CPU twins differ");
        // Baseline, one thread.
        let (base, base_s) = best_of(|| {
            cases
                .iter()
                .map(|c| vieta_crossings(&c.corners, c.o, c.d, c.l, c.tau))
                .collect::<Vec<_>>()
        });

        let (mut sg, mut scpu, mut sb) = (Score::default(), Score::default(), Score::default());
        let mut identical = 0;
        for (i, oc) in orc.iter().enumerate() {
            let gi = r.start + i;
            let (g, gbad) = ours(&gout, gi);
            let (c, cbad) = ours(&cout, i);
            identical += (gout.get(gi) == cout.get(i)) as usize;
            sg.add(&score_case(oc, &g, gbad));
            scpu.add(&score_case(oc, &c, cbad));
            let b: Vec<(f64, bool)> = base[i].crossings.iter().map(|x| (x.s, x.rising)).collect();
            sb.add(&score_case(oc, &b, base[i].non_finite > 0));
        }
        let pass = sg.meets_targets()
            && scpu.meets_targets()
            && sg.not_worse_than(&sb)
            && scpu.not_worse_than(&sb);
        rows.push(ClassRow {
            class: class.name(),
            cases: n,
            oracle_crossings: orc.iter().map(|o| o.crossings.len()).sum(),
            gpu: sg,
            cpu: scpu,
            baseline: sb,
            gpu_solves_per_s: n as f64 / (gns[k] * 1e-9),
            cpu_solves_per_s: n as f64 / cpu_s,
            cpu1_solves_per_s: n as f64 / cpu1_s,
            baseline1_solves_per_s: n as f64 / base_s,
            gpu_cpu_identical: identical,
            pass,
        });
    }
    let total = |f: &dyn Fn(&ClassRow) -> &Score| {
        let mut s = Score::default();
        for r in &rows {
            s.add(f(r));
        }
        s
    };
    let (tg, tc, tb) = (
        total(&|r| &r.gpu),
        total(&|r| &r.cpu),
        total(&|r| &r.baseline),
    );
    let all_n = (n * classes.len()) as f64;
    let gpu_rate = all_n / (gns.iter().sum::<f64>() * 1e-9);
    let messages = gpu.validation_messages();
    let pass = rows.iter().all(|r| r.pass) && messages.is_empty();

    println!(
        "cubic stress suite: {n} cases per class, seed {}, device {} ({})",
        args.seed,
        gpu.info().name,
        gpu.info().driver
    );
    println!(
        "floor: oracle crossings with |f'(s)|·L < {FLOOR:.0e}·max|δ−τ| are near-tangent (excluded, counted; \
         'band m/s' = missed/spurious with {FLOOR_BAND:.0e} ≤ |f'|·L/max|δ−τ| < {FLOOR:.0e}); missed rate per \
         significant oracle crossing, spurious rate per case; 'face' = owner cell decided below f32 resolution"
    );
    println!(
        "{:<14} {:<8} {:>8} {:>7} {:>7} {:>9} {:>9} {:>7} {:>9} {:>6} {:>9} {:>6} {:>10}",
        "class",
        "solver",
        "signif",
        "missed",
        "spur",
        "miss rate",
        "spur rate",
        "tangent",
        "band m/s",
        "face",
        "max|Δs|",
        "NaN",
        "solves/s"
    );
    for r in &rows {
        let line = |name: &str, s: &Score, rate: f64| {
            println!(
                "{:<14} {:<8} {:>8} {:>7} {:>7} {:>9.1e} {:>9.1e} {:>7} {:>9} {:>6} {:>9.2e} {:>6} {:>10.3e}",
                r.class,
                name,
                s.significant,
                s.missed,
                s.spurious,
                s.missed_rate(),
                s.spurious_rate(),
                s.near_tangent,
                format!("{}/{}", s.band_missed, s.band_spurious),
                s.face_ambiguous,
                s.max_ds,
                s.non_finite,
                rate
            )
        };
        line("vulkan", &r.gpu, r.gpu_solves_per_s);
        line("cpu", &r.cpu, r.cpu_solves_per_s);
        line("vieta64", &r.baseline, r.baseline1_solves_per_s);
        println!(
            "{:<14} cpu 1-thread {:.3e}/s; vulkan == cpu bit-exact in {}/{} cases; {}",
            "",
            r.cpu1_solves_per_s,
            r.gpu_cpu_identical,
            r.cases,
            if r.pass { "pass" } else { "FAIL" }
        );
    }
    let cpu_rate = all_n
        / rows
            .iter()
            .map(|r| n as f64 / r.cpu_solves_per_s)
            .sum::<f64>();
    let cpu1_rate = all_n
        / rows
            .iter()
            .map(|r| n as f64 / r.cpu1_solves_per_s)
            .sum::<f64>();
    let base_rate = all_n
        / rows
            .iter()
            .map(|r| n as f64 / r.baseline1_solves_per_s)
            .sum::<f64>();
    println!(
        "overall: vulkan {gpu_rate:.3e} solves/s (device time), cpu {cpu_rate:.3e}/s ({} threads), cpu 1-thread {cpu1_rate:.3e}/s, vieta64 1-thread {base_rate:.3e}/s",
        rayon::current_num_threads()
    );
    println!(
        "overall missed/spurious/max|Δs|/NaN: vulkan {}/{}/{:.2e}/{}, cpu {}/{}/{:.2e}/{}, vieta64 {}/{}/{:.2e}/{}",
        tg.missed, tg.spurious, tg.max_ds, tg.non_finite, tc.missed, tc.spurious, tc.max_ds, tc.non_finite,
        tb.missed, tb.spurious, tb.max_ds, tb.non_finite
    );
    for m in &messages {
        println!("validation: {m}");
    }
    println!(
        "{} ({:.1} s)",
        if pass { "PASS" } else { "FAIL" },
        t0.elapsed().as_secs_f64()
    );
    if args.json {
        println!(
            "{}",
            serde_json::json!({
                "bench": "cubic",
                "device": gpu.info().name,
                "cases_per_class": n,
                "seed": args.seed,
                "floor": FLOOR,
                "boundary_rel": BOUNDARY_REL,
                "targets": {"rate": RATE_TARGET, "max_ds": DS_TARGET},
                "classes": rows,
                "overall": {
                    "gpu": tg, "cpu": tc, "baseline": tb,
                    "gpu_solves_per_s": gpu_rate, "cpu_solves_per_s": cpu_rate,
                    "cpu1_solves_per_s": cpu1_rate, "baseline1_solves_per_s": base_rate,
                },
                "validation_messages": messages,
                "pass": pass,
            })
        );
    }
    Ok(pass)
}
