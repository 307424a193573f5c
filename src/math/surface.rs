//! Stage-2 (αSurf) surface rendering pieces (method.md §3.2, §5): the twin of
//! `glsl/lib/surface.glsl` (same operations in the same order, no FMA contraction where the GLSL is
//! `precise` without `fma`).
//!
//! grid = p·scale + offset and the grid-space direction is normalised, so t and s are in voxels.
//! A cell's piece [t0, t1] of the DDA walk has entry point q0 = P(t0) − l and exit point
//! q1 = P(t1) − l with P(t) = og + t·dn, clamped to [0,1]³, and exactly 0 or 1 on every axis
//! whose cell face the DDA crosses at that t (the same plane time as the walk's): the exit of one
//! cell and the entry of the next are then the same point of their shared face, edge or corner,
//! a level's value there is the same trilerp of the shared corners on both sides, and a crossing
//! there belongs to the entered cell, which is told the sign before it ([`FaceSigns`]).

use super::background_msi::{BackgroundView, SphereTable};
use super::cubic::{exit_sign, solve_crossings, trilerp_level, CellCubic};
use super::dda::{ray_unit, Dda};
use super::madd::madd;
use super::trilerp::trilerp;
use crate::abi::consts::{SURF_COUNT_RAY, SURF_COUNT_STRUCTURE, SURF_COUNT_THROUGH};
use std::sync::Arc;

pub use crate::abi::consts::{SURF_MAX_LEVELS, SURF_SEGMENT_MARGIN};
/// Bound of a cell's hit list: ≤ 3 crossings per level.
pub const SURF_MAX_CELL_HITS: usize = 24;

pub use crate::abi::buffers::SurfOut;

/// Scene ray (ro, rd) → grid origin `ro·scale + offset` and unit grid direction.
pub fn surf_ray(
    ro: [f32; 3],
    rd: [f32; 3],
    scale: [f32; 3],
    offset: [f32; 3],
) -> ([f32; 3], [f32; 3]) {
    let og = std::array::from_fn(|i| madd(ro[i], scale[i], offset[i]));
    let dg = std::array::from_fn(|i| rd[i] * scale[i]);
    (og, ray_unit(dg))
}

/// Local coordinates in cell `l` of og + t·dn, clamped to [0,1]³; an axis whose lower or upper
/// cell plane the walk `w` crosses at exactly `t` (its plane time ((plane − o)·1/d, the DDA's own
/// expression) equals t) is put exactly on that face.
pub fn surf_local(w: &Dda, og: [f32; 3], dn: [f32; 3], t: f32, l: [i32; 3]) -> [f32; 3] {
    std::array::from_fn(|a| {
        let q = (madd(t, dn[a], og[a]) - l[a] as f32).clamp(0.0, 1.0);
        if w.step[a] == 0 {
            q
        } else if (l[a] as f32 - w.o[a]) * w.inv[a] == t {
            0.0
        } else if ((l[a] + 1) as f32 - w.o[a]) * w.inv[a] == t {
            1.0
        } else {
            q
        }
    })
}

/// Per level, the sign of δ − τ just before the exit of the last solved cell of a ray's walk
/// (bit i of `pos`/`neg`; neither when unknown) and that exit's t: the next solved cell uses them
/// only when it starts at that t, i.e. shares that face point.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FaceSigns {
    pub t: f32,
    pub pos: u32,
    pub neg: u32,
}

impl FaceSigns {
    /// The signs before a cell entered at `t0` (none unless the previous solved cell ended there).
    pub fn before(&self, t0: f32) -> FaceSigns {
        if t0 == self.t {
            *self
        } else {
            FaceSigns::default()
        }
    }

    /// Level i's sign: ±1, or 0 when unknown.
    pub fn sign(&self, i: usize) -> f32 {
        if self.pos & (1 << i) != 0 {
            1.0
        } else if self.neg & (1 << i) != 0 {
            -1.0
        } else {
            0.0
        }
    }
}

/// A cell's sorted front-face hits (s values).
#[derive(Clone, Copy, Debug)]
pub struct CellHits {
    pub n: usize,
    pub s: [f32; SURF_MAX_CELL_HITS],
    /// Level index of each hit.
    pub level: [u32; SURF_MAX_CELL_HITS],
    /// The solved levels' signs before the exit (`t` left 0 for the caller to set).
    pub exit: FaceSigns,
    /// Level 0's front crossings among the hits, ascending ([`SURF_NO_HIT`] where there are
    /// fewer than two), for [`surf_restart`].
    pub outer: [f32; 2],
}

/// An empty slot of a hit list (the GLSL's `SURF_NO_HIT`).
pub const SURF_NO_HIT: f32 = f32::MAX;

/// How the truncation count j of γ_a(j) runs along a ray (`SurfParams::truncation_count`).
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    serde::Serialize,
    serde::Deserialize,
    clap::ValueEnum,
)]
#[serde(rename_all = "lowercase")]
pub enum TruncationCount {
    /// Over every front hit of the ray (the paper's rule): the ray ends at its first hit j ≥ a.
    #[default]
    Ray,
    /// Per structure: the count restarts where the ray enters level 0 (the outermost level) from
    /// outside ([`RayCount::restart`]); a truncated hit is passed over, not the end of the ray.
    Structure,
    /// Per structure as `Structure`, but each structure behind the first the ray enters gets
    /// its first hit alone (its outermost level): a surface seen through another is composited,
    /// while its inner levels are composited only by rays that meet it first.
    Through,
}

/// Truncated compositing: γ_a(k) with k counted as `count` says.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Truncation {
    pub a: f32,
    pub count: TruncationCount,
}

/// The paper's rule with parameter `a`.
impl From<f32> for Truncation {
    fn from(a: f32) -> Self {
        Truncation {
            a,
            count: TruncationCount::Ray,
        }
    }
}

impl TruncationCount {
    /// `SurfParams::truncation_count`.
    pub fn code(self) -> u32 {
        match self {
            TruncationCount::Ray => SURF_COUNT_RAY,
            TruncationCount::Structure => SURF_COUNT_STRUCTURE,
            TruncationCount::Through => SURF_COUNT_THROUGH,
        }
    }

    /// The count's name in configurations and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            TruncationCount::Ray => "ray",
            TruncationCount::Structure => "structure",
            TruncationCount::Through => "through",
        }
    }

    /// Whether a truncated hit is passed over (while T ≥ `SURF_PASS_MIN_T`) rather than ending
    /// the ray: when a later structure may restart the count.
    pub fn passes_over(self) -> bool {
        self != TruncationCount::Ray
    }
}

/// The truncation count of a ray as it walks under truncation `t`: `k` hits counted, a hit
/// truncated (γ = 0) from `k ≥ limit`; `structures` entered so far. (The GLSL keeps the three in
/// registers.)
#[derive(Clone, Copy, Debug)]
pub struct RayCount {
    t: Truncation,
    pub k: u32,
    pub limit: f32,
    structures: u32,
}

impl RayCount {
    /// A ray's count under `t` before its first hit.
    pub fn new(t: Truncation) -> Self {
        RayCount {
            t,
            k: 0,
            limit: t.a,
            structures: 0,
        }
    }

    /// Counting per structure: a popped hit `s` that is one of the cell's front crossings of
    /// level 0 (`outer`; the outermost level, as levels increase) is where the ray enters a
    /// structure from outside every level set, so the count restarts at 0 there, its limit `a`
    /// (`Structure`, and the first structure of `Through`) or 1 (the structures behind it with
    /// `Through`); each structure along the ray gets its own first hits, and the inner levels of
    /// one structure are still truncated. A matched value is consumed: of two equal hits one
    /// restarts the count. (The GLSL's `surf_restart`: the kernels' hit lists hold s values only.)
    pub fn restart(&mut self, s: f32, outer: &mut [f32; 2]) {
        let Truncation { a, count } = self.t;
        if count == TruncationCount::Ray {
            return;
        }
        if s == outer[0] {
            outer[0] = SURF_NO_HIT;
        } else if s == outer[1] {
            outer[1] = SURF_NO_HIT;
        } else {
            return;
        }
        self.k = 0;
        self.limit = if count == TruncationCount::Through && self.structures > 0 {
            a.min(1.0)
        } else {
            a
        };
        self.structures += 1;
    }

    /// Whether the next hit is truncated.
    pub fn truncated(&self) -> bool {
        self.k as f32 >= self.limit
    }

    /// Whether a truncated hit is passed over ([`TruncationCount::passes_over`]).
    pub fn passes_over(&self) -> bool {
        self.t.count.passes_over()
    }
}

impl CellHits {
    fn insert(&mut self, s: f32, level: u32) {
        let mut i = self.n;
        while i > 0 && self.s[i - 1] > s {
            self.s[i] = self.s[i - 1];
            self.level[i] = self.level[i - 1];
            i -= 1;
        }
        self.s[i] = s;
        self.level[i] = level;
        self.n += 1;
    }

    /// The hits in order.
    pub fn as_slice(&self) -> &[f32] {
        &self.s[..self.n]
    }

    /// The level index of each hit, in the same order.
    pub fn levels(&self) -> &[u32] {
        &self.level[..self.n]
    }
}

/// The smallest and largest of a cell's 8 corner values (pairwise, as the GLSL's nested min/max).
pub fn surf_cell_range(c: &[f32; 8]) -> (f32, f32) {
    let cmin = c[0]
        .min(c[1])
        .min(c[2].min(c[3]))
        .min(c[4].min(c[5]).min(c[6].min(c[7])));
    let cmax = c[0]
        .max(c[1])
        .max(c[2].max(c[3]))
        .max(c[4].max(c[5]).max(c[6].max(c[7])));
    (cmin, cmax)
}

/// Min/max culling: bit i set when `levels[i]` (at most [`SURF_MAX_LEVELS`]) lies within
/// [min c, max c]; only those levels can cross the cell.
pub fn surf_level_mask(c: &[f32; 8], levels: &[f32]) -> u32 {
    let (cmin, cmax) = surf_cell_range(c);
    levels
        .iter()
        .take(SURF_MAX_LEVELS)
        .enumerate()
        .filter(|(_, &tau)| cmin <= tau && tau <= cmax)
        .fold(0, |m, (i, _)| m | 1 << i)
}

/// Segment culling: the levels of `mask` (from [`surf_level_mask`]) that can cross the ray's
/// piece of the cell, corners `c`, entry/exit points `q0`/`q1`, `cc` = `cell_cubic(c, q0, d)`,
/// length `l`. Along the piece δ − τ is the cubic f(s) = β0 + C1·s + C2·s² + C3·s³, whose Bernstein
/// coefficients on [0, L] bound it (convex hull): b0 = f(0), b1 = b0 + C1L/3,
/// b2 = b0 + (2·C1L + C2L²)/3, b3 = b0 + C1L + C2L² + C3L³; the solver also reads the exit value
/// e = δ(q1) − τ. A level is dropped when b0..b3 and e all exceed m or all lie below −m,
/// m = SURF_SEGMENT_MARGIN·(|b0| + |C1L| + |C2L²| + |C3L³| + max|c| + |τ|): then f stays that far
/// from 0 on the whole piece, while the solver's values (its own f(0) and e, evaluated at the
/// critical points, snapped to 0 within 2^-22 of their magnitude) differ from these by a few
/// rounding units of the same magnitudes, so it would find no crossing (tested against the
/// solver, `segment_culling_drops_only_levels_without_crossings`). A level dropped here saves its
/// solve, and a cell left without levels is walked past like an empty one.
pub fn surf_segment_mask(
    c: &[f32; 8],
    cc: CellCubic,
    q0: [f32; 3],
    q1: [f32; 3],
    l: f32,
    levels: &[f32],
    mask: u32,
) -> u32 {
    let v0 = trilerp(c, q0);
    let v1 = trilerp(c, q1);
    let a1 = cc.c1 * l;
    let a2 = (cc.c2 * l) * l;
    let a3 = ((cc.c3 * l) * l) * l;
    let cabs = c.iter().fold(0f32, |m, x| m.max(x.abs()));
    let size = ((a1.abs() + a2.abs()) + a3.abs()) + cabs;
    let mut out = 0;
    for (i, &tau) in levels.iter().enumerate().take(SURF_MAX_LEVELS) {
        if mask & (1 << i) == 0 {
            continue;
        }
        let b0 = v0 - tau;
        let b1 = b0 + a1 / 3.0;
        let b2 = b0 + madd(2.0, a1, a2) / 3.0;
        let b3 = ((b0 + a1) + a2) + a3;
        let e = v1 - tau;
        let m = SURF_SEGMENT_MARGIN * ((b0.abs() + size) + tau.abs());
        let lo = b0.min(b1).min(b2.min(b3)).min(e);
        let hi = b0.max(b1).max(b2.max(b3)).max(e);
        if !(lo > m || hi < -m) {
            out |= 1 << i;
        }
    }
    out
}

/// Front-face (rising) crossings in one cell of the levels in `mask` (from
/// [`surf_segment_mask`]), sorted by s ∈ [0, L): corners `c` (paper order), `cc` =
/// `cell_cubic(c, q0, d)` (C1..C3, formed once per cell), entry/exit points; each level solves
/// with its own exact end values and the sign before the entry point from `before`
/// (`FaceSigns::before`); `outer` holds level 0's front crossings.
#[allow(clippy::too_many_arguments)]
pub fn surf_cell_hits(
    c: &[f32; 8],
    cc: CellCubic,
    q0: [f32; 3],
    q1: [f32; 3],
    l: f32,
    levels: &[f32],
    mut mask: u32,
    before: FaceSigns,
) -> CellHits {
    let mut out = CellHits {
        n: 0,
        s: [0.0; SURF_MAX_CELL_HITS],
        level: [0; SURF_MAX_CELL_HITS],
        exit: FaceSigns::default(),
        outer: [SURF_NO_HIT; 2],
    };
    while mask != 0 {
        let i = mask.trailing_zeros() as usize;
        mask &= mask - 1;
        let tau = levels[i];
        let ends = [trilerp_level(c, q0, tau), trilerp_level(c, q1, tau)];
        let b = before.sign(i);
        let x = solve_crossings(cc, ends, l, b);
        for (s, rising) in x.iter() {
            if rising {
                out.insert(s, i as u32);
                if i == 0 {
                    // ≤ 2 per cell: rising and falling crossings alternate, ≤ 3 roots.
                    if out.outer[0] == SURF_NO_HIT {
                        out.outer[0] = s;
                    } else if out.outer[1] == SURF_NO_HIT {
                        out.outer[1] = s;
                    }
                }
            }
        }
        let e = exit_sign(&x, ends[0], b);
        if e > 0.0 {
            out.exit.pos |= 1 << i;
        } else if e < 0.0 {
            out.exit.neg |= 1 << i;
        }
    }
    out
}

/// Truncation weight γ_a(j) = ½(1 − cos(π·clamp(a − j, 0, 1))): exactly 1 for j ≤ a − 1 and
/// exactly 0 for j ≥ a.
pub fn surf_gamma(a: f32, j: u32) -> f32 {
    let u = (a - j as f32).clamp(0.0, 1.0);
    if u >= 1.0 {
        return 1.0;
    }
    if u <= 0.0 {
        return 0.0;
    }
    0.5 * (1.0 - (std::f32::consts::PI * u).cos())
}

/// α = 1 − exp(−max(σα, 0)) (no step length).
pub fn surf_alpha(sa: f32) -> f32 {
    1.0 - (-sa.max(0.0)).exp()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::cubic::cell_cubic;

    #[test]
    fn counts_restart_per_structure_and_through_keeps_one_hit_behind_the_first() {
        // Two structures along the ray: levels 0, 1, 2 of the first at s = 0.1, 0.2, 0.3, levels
        // 0, 1 of the second at 0.6, 0.7 (the level-0 crossings are the cells' `outer` hits).
        let hits = [0.1f32, 0.2, 0.3, 0.6, 0.7];
        let a = 2.0;
        for (count, want) in [
            (TruncationCount::Ray, [true, true, false, false, false]),
            (TruncationCount::Structure, [true, true, false, true, true]),
            (TruncationCount::Through, [true, true, false, true, false]),
        ] {
            let mut rc = RayCount::new(Truncation { a, count });
            let kept = hits.map(|s| {
                let mut outer = if s == 0.1 || s == 0.6 {
                    [s, SURF_NO_HIT]
                } else {
                    [SURF_NO_HIT; 2]
                };
                rc.restart(s, &mut outer);
                let keep = !rc.truncated();
                rc.k += u32::from(keep);
                keep
            });
            assert_eq!(kept, want, "{count:?}");
            assert_eq!(count.passes_over(), count != TruncationCount::Ray);
            assert_eq!(
                serde_json::to_value(count).unwrap(),
                serde_json::Value::from(count.name())
            );
        }
        // While a decays above 1, a structure behind the first still keeps one hit.
        let mut rc = RayCount::new(Truncation {
            a: 3.4,
            count: TruncationCount::Through,
        });
        let mut outer = [0.5, SURF_NO_HIT];
        rc.restart(0.1, &mut [0.1, SURF_NO_HIT]);
        rc.k = 3;
        rc.restart(0.5, &mut outer);
        assert_eq!((rc.k, rc.limit, outer[0]), (0, 1.0, SURF_NO_HIT));
    }

    #[test]
    fn gamma_ends_and_blend() {
        assert_eq!(surf_gamma(1.0, 0), 1.0);
        assert_eq!(surf_gamma(1.0, 1), 0.0);
        assert_eq!(surf_gamma(5.0, 4), 1.0);
        assert_eq!(surf_gamma(5.0, 5), 0.0);
        assert!((surf_gamma(2.5, 2) - 0.5).abs() < 1e-6);
        // cos(π/4) = √½: γ = ½(1 − √½).
        assert!((surf_gamma(2.25, 2) - 0.5 * (1.0 - 0.5f32.sqrt())).abs() < 1e-6);
        assert_eq!(surf_alpha(-3.0), 0.0);
    }

    #[test]
    fn cell_hits_sorted_front_faces_only() {
        // δ = x over the cell: along +x every level in (0, 1) is one rising crossing at s = τ;
        // along −x the same crossings fall (no hits).
        let c = [0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0];
        let levels = [0.7, 0.2, 0.5, 2.0];
        let mask = surf_level_mask(&c, &levels);
        assert_eq!(mask, 0b0111);
        let h = surf_cell_hits(
            &c,
            cell_cubic(&c, [0.0, 0.5, 0.5], [1.0, 0.0, 0.0]),
            [0.0, 0.5, 0.5],
            [1.0, 0.5, 0.5],
            1.0,
            &levels,
            mask,
            FaceSigns::default(),
        );
        assert_eq!(h.n, 3);
        for (s, want) in h.as_slice().iter().zip([0.2, 0.5, 0.7]) {
            assert!((s - want).abs() < 1e-6, "{s} {want}");
        }
        let h = surf_cell_hits(
            &c,
            cell_cubic(&c, [1.0, 0.5, 0.5], [-1.0, 0.0, 0.0]),
            [1.0, 0.5, 0.5],
            [0.0, 0.5, 0.5],
            1.0,
            &levels,
            mask,
            FaceSigns::default(),
        );
        assert_eq!(h.n, 0);
    }

    /// Segment culling never drops a level the solver finds a crossing of: random cells at several
    /// scales and offsets, pieces from a face to the exit, and levels that are random, on a corner,
    /// at the entry or exit value, or at a critical value of the piece's cubic (tangent, the
    /// closest calls), nudged by ±1e-7..1e-3 relative.
    #[test]
    fn segment_culling_drops_only_levels_without_crossings() {
        use crate::math::cubic::exit_point;
        use rand::{Rng, SeedableRng};
        use rand_pcg::Pcg64;
        let mut rng = Pcg64::seed_from_u64(23);
        let (mut solved, mut dropped, mut dropped_near) = (0u32, 0u32, 0u32);
        for trial in 0..40_000 {
            let scale = [1e-3f32, 1.0, 30.0, 1e3][trial % 4];
            let offset = [0.0f32, 0.0, 100.0, -7.5][(trial / 4) % 4];
            let c: [f32; 8] = std::array::from_fn(|_| rng.random_range(-1.0..1.0) * scale + offset);
            // Entry on the face the direction enters through; the piece runs to the exit.
            let mut d: [f32; 3] = std::array::from_fn(|_| rng.random_range(-1.0f32..1.0));
            if trial % 7 == 0 {
                d[trial % 3] = 0.0; // parallel to a face
            }
            let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            if n < 1e-3 {
                continue;
            }
            let d = d.map(|x| x / n);
            let a = (0..3)
                .max_by(|&i, &j| d[i].abs().total_cmp(&d[j].abs()))
                .unwrap();
            let mut q0: [f32; 3] = std::array::from_fn(|_| rng.random_range(0.0..1.0));
            q0[a] = if d[a] > 0.0 { 0.0 } else { 1.0 };
            let l = (0..3)
                .filter(|&i| d[i] != 0.0)
                .map(|i| (if d[i] > 0.0 { 1.0 - q0[i] } else { -q0[i] }) / d[i])
                .fold(f32::MAX, f32::min);
            if !(l > 0.0) {
                continue;
            }
            let q1 = exit_point(q0, d, l);
            let cc = cell_cubic(&c, q0, d);
            // f(s) = δ(q0 + s·d) along the piece, in f64 from the corners.
            let at = |s: f64| -> f64 {
                let p: [f64; 3] = std::array::from_fn(|i| q0[i] as f64 + s * d[i] as f64);
                (0..8)
                    .map(|i| {
                        let w = |b: usize, x: f64| if (i >> b) & 1 == 1 { x } else { 1.0 - x };
                        c[i] as f64 * w(2, p[0]) * w(1, p[1]) * w(0, p[2])
                    })
                    .sum()
            };
            let mut levels = vec![
                rng.random_range(-1.0..1.0) * scale + offset,
                c[rng.random_range(0..8)],
                trilerp(&c, q0),
                trilerp(&c, q1),
            ];
            // Critical values: roots of C1 + 2·C2·s + 3·C3·s² in (0, L).
            let (c1, c2, c3) = (cc.c1 as f64, cc.c2 as f64, cc.c3 as f64);
            let disc = c2 * c2 - 3.0 * c3 * c1;
            if disc >= 0.0 && c3 != 0.0 {
                for r in [
                    (-c2 + disc.sqrt()) / (3.0 * c3),
                    (-c2 - disc.sqrt()) / (3.0 * c3),
                ] {
                    if r > 0.0 && r < l as f64 {
                        levels.push(at(r) as f32);
                    }
                }
            }
            let base = levels.clone();
            for &tau in &base {
                let nudge = [1e-7f32, -1e-7, 1e-5, -1e-5, 1e-3][rng.random_range(0..5)];
                levels.push(tau + nudge * (tau.abs() + scale));
            }
            for chunk in levels.chunks(SURF_MAX_LEVELS) {
                let all = (1u32 << chunk.len()) - 1;
                let keep = surf_segment_mask(&c, cc, q0, q1, l, chunk, all);
                for (i, &tau) in chunk.iter().enumerate() {
                    let ends = [trilerp_level(&c, q0, tau), trilerp_level(&c, q1, tau)];
                    let x = solve_crossings(cc, ends, l, 0.0);
                    solved += 1;
                    if keep & (1 << i) != 0 {
                        continue;
                    }
                    dropped += 1;
                    assert_eq!(
                        x.n, 0,
                        "dropped level {tau} has crossings {x:?}: corners {c:?}, q0 {q0:?}, \
                         d {d:?}, L {l}"
                    );
                    // Dropped within 1 % of the margin's scale of the curve: the close calls.
                    let lo = (0..=64)
                        .map(|k| (at(l as f64 * k as f64 / 64.0) - tau as f64).abs())
                        .fold(f64::MAX, f64::min);
                    if lo < 1e-3 * (tau.abs() + scale) as f64 {
                        dropped_near += 1;
                    }
                }
            }
        }
        // Not vacuous: most levels are dropped, some of them close to the curve.
        assert!(dropped > solved / 3, "{dropped} of {solved} dropped");
        assert!(dropped_near > 1000, "only {dropped_near} close calls");
    }
}

/// How rays map into the grid, the levels, truncation and early termination.
#[derive(Clone, Debug)]
pub struct SurfaceParams {
    /// grid = p·scale + offset (per axis).
    pub scale: [f32; 3],
    pub offset: [f32; 3],
    /// Level values τ_i (at most [`SURF_MAX_LEVELS`]).
    pub levels: Vec<f32>,
    /// Truncated compositing: hits with count k ≥ a get γ = 0 (the ray stops there, or with
    /// counting per structure passes them over).
    pub truncation: Truncation,
    /// Stop once transmittance falls below this.
    pub stop_thresh: f32,
    /// The colour composited behind the last hit: C = Σ w_j c_j + T·B, B the colour behind
    /// `spheres` when there are any.
    pub background: [f32; 3],
    pub spheres: Option<Arc<SphereTable>>,
}

impl SurfaceParams {
    /// What a ray meets behind the last hit, as the twins read it.
    pub fn behind(&self) -> BackgroundView<'_> {
        BackgroundView::new(self.background, self.spheres.as_deref())
    }

    /// These parameters with the background's `spheres` behind the grid.
    pub fn with_spheres(self, spheres: Option<Arc<SphereTable>>) -> Self {
        SurfaceParams { spheres, ..self }
    }
}
