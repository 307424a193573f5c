//! Ray/level-set intersection inside one cell, in f32: the CPU twin of `glsl/lib/cubic.glsl`
//! (same formulation and operation order; GLSL `fma` is `f32::mul_add` here).
//!
//! Along a ray p(s) = o′ + s·d inside a cell (o′ ∈ [0,1]³, unit d in voxel units, s ∈ [0, L]) the
//! trilinear field is a cubic f(s) = C3·s³ + C2·s² + C1·s + C0 (method.md §3.2). C1..C3 are shared
//! by every level of the cell ([`cell_cubic`]); for a level τ only the constant term changes, and
//! [`level_ends`] forms f(0) = C0 − τ and f(L) as trilerps of the corners minus τ (at the entry
//! and exit points), so that nearly flat cells keep their precision and a level through a cell face
//! is decided exactly. [`solve_crossings`] returns the sign-change crossings of f on [0, L).
//!
//! Corner order is the paper's: index i = 4a + 2b + c with a the x bit, b the y bit, c the z bit.

use super::madd::madd;

pub use crate::abi::consts::{
    CUBIC_CRIT_SNAP, CUBIC_MAX_ITERS, CUBIC_MAX_L, CUBIC_MERGE_EPS, CUBIC_SNAP, CUBIC_STEP_TOL,
};

/// The coefficients of a cell's cubic that do not depend on the level.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CellCubic {
    pub c1: f32,
    pub c2: f32,
    pub c3: f32,
}

/// Up to three crossings, sorted by s; `rising[i]` when f − τ goes from < 0 to > 0 along the ray.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Crossings {
    pub n: u32,
    pub s: [f32; 3],
    pub rising: [bool; 3],
}

impl Crossings {
    /// Append a crossing (at most three).
    pub fn push(&mut self, s: f32, rising: bool) {
        let i = self.n as usize;
        self.s[i] = s;
        self.rising[i] = rising;
        self.n += 1;
    }

    /// The first `n` crossings as (s, rising).
    pub fn iter(&self) -> impl Iterator<Item = (f32, bool)> + '_ {
        (0..self.n as usize).map(|i| (self.s[i], self.rising[i]))
    }
}

/// FMA-shaped lerp, exact at t = 0 and t = 1: `fma(t, b, fma(−t, a, a))`.
#[inline(always)]
pub fn lerp(a: f32, b: f32, t: f32) -> f32 {
    t.mul_add(b, (-t).mul_add(a, a))
}

/// C1, C2, C3 for the ray o′ + s·d through a cell with corners `corners` (paper order).
/// Computed from the corners minus corner 000 (exact for nearly flat cells; the coefficients of
/// s¹..s³ do not change when a constant is added to every corner), then method.md's lerp/FMA lines.
pub fn cell_cubic(corners: &[f32; 8], o: [f32; 3], d: [f32; 3]) -> CellCubic {
    let w = |i: usize| corners[i] - corners[0];
    let [ox, oy, oz] = o;
    let [dx, dy, dz] = d;
    // m_ab = lerp(δ_ab0, δ_ab1, o_z), e_ab = δ_ab1 − δ_ab0 with ab = 00, 01, 10, 11.
    let (w0, w1, w2, w3, w4, w5, w6, w7) = (w(0), w(1), w(2), w(3), w(4), w(5), w(6), w(7));
    let m00 = lerp(w0, w1, oz);
    let m01 = lerp(w2, w3, oz);
    let m10 = lerp(w4, w5, oz);
    let m11 = lerp(w6, w7, oz);
    let e00 = w1 - w0;
    let e01 = w3 - w2;
    let e10 = w5 - w4;
    let e11 = w7 - w6;
    let n0 = lerp(m00, m01, oy);
    let n1 = lerp(m10, m11, oy);
    let k0 = dy.mul_add(m01 - m00, dz * lerp(e00, e01, oy));
    let k1 = dy.mul_add(m11 - m10, dz * lerp(e10, e11, oy));
    let dyz = dy * dz;
    let h0 = dyz * (e01 - e00);
    let h1 = dyz * (e11 - e10);
    CellCubic {
        c3: dx * (h1 - h0),
        c2: dx.mul_add(k1 - k0, lerp(h0, h1, ox)),
        c1: dx.mul_add(n1 - n0, lerp(k0, k1, ox)),
    }
}

/// δ(p) − τ as the trilerp at p of the corners minus τ (subtracting τ first avoids cancellation).
pub fn trilerp_level(corners: &[f32; 8], p: [f32; 3], tau: f32) -> f32 {
    let [ox, oy, oz] = p;
    let m00 = lerp(corners[0] - tau, corners[1] - tau, oz);
    let m01 = lerp(corners[2] - tau, corners[3] - tau, oz);
    let m10 = lerp(corners[4] - tau, corners[5] - tau, oz);
    let m11 = lerp(corners[6] - tau, corners[7] - tau, oz);
    lerp(lerp(m00, m01, oy), lerp(m10, m11, oy), ox)
}

/// Exit point o′ + L·d, clamped to the cell; its coordinate nearest a face is snapped onto the face
/// when within [`CUBIC_SNAP`] (a chord leaves through a face, so this only undoes rounding, and the level
/// through that face is then decided by the same corner values as in the next cell).
pub fn exit_point(o: [f32; 3], d: [f32; 3], l: f32) -> [f32; 3] {
    let mut q = [0, 1, 2].map(|k| l.mul_add(d[k], o[k]).clamp(0.0, 1.0));
    let dq = q.map(|v| v.min(1.0 - v));
    let k = if dq[0] <= dq[1] && dq[0] <= dq[2] {
        0
    } else if dq[1] <= dq[2] {
        1
    } else {
        2
    };
    if dq[k] <= CUBIC_SNAP {
        q[k] = if q[k] > 0.5 { 1.0 } else { 0.0 };
    }
    q
}

/// The level's end values [f(0), f(L)] = [C0 − τ, δ(exit) − τ], both as trilerps of the corners
/// minus τ. f(L) is taken at the exit point rather than from the coefficients so that a crossing on
/// the exit face is decided by the same arithmetic as the next cell's f(0) (exactly, when the exit
/// point equals the next cell's entry point), and a level through the exit face is exactly zero.
pub fn level_ends(corners: &[f32; 8], o: [f32; 3], d: [f32; 3], l: f32, tau: f32) -> [f32; 2] {
    [
        trilerp_level(corners, o, tau),
        trilerp_level(corners, exit_point(o, d, l), tau),
    ]
}

/// Horner evaluation of the cubic (c[0] + c[1]s + c[2]s² + c[3]s³) with FMAs.
#[inline(always)]
pub fn eval(c: &[f32; 4], s: f32) -> f32 {
    c[3].mul_add(s, c[2]).mul_add(s, c[1]).mul_add(s, c[0])
}

/// Horner evaluation of the derivative 3c[3]s² + 2c[2]s + c[1].
#[inline(always)]
pub fn eval_deriv(c: &[f32; 4], s: f32) -> f32 {
    (3.0 * c[3]).mul_add(s, 2.0 * c[2]).mul_add(s, c[1])
}

/// f at a critical point, snapped to 0 within its rounding noise (see [`CUBIC_CRIT_SNAP`]).
#[inline(always)]
fn crit_value(c: &[f32; 4], s: f32) -> f32 {
    let v = eval(c, s);
    let mag = c[3]
        .abs()
        .mul_add(s, c[2].abs())
        .mul_add(s, c[1].abs())
        .mul_add(s, c[0].abs());
    if v.abs() <= CUBIC_CRIT_SNAP * mag {
        0.0
    } else {
        v
    }
}

/// Power of two that brings `m` (> 0, finite) into [0.5, 1), clamped to a normal f32.
#[inline(always)]
pub fn pow2_scale(m: f32) -> f32 {
    let e = ((m.to_bits() >> 23) & 0xff) as i32;
    let se = (253 - e).clamp(1, 254) as u32;
    f32::from_bits(se << 23)
}

/// Safeguarded Newton/bisection (Numerical Recipes' rtsafe) for the root of the cubic `c` in the
/// bracket (lo, hi) whose end values `flo`, `fhi` have strictly opposite signs. Starts from the
/// regula-falsi point; a Newton step that would leave the bracket or converge too slowly is
/// replaced by bisection; the bracket shrinks on every evaluation. Stops when a step is ≤ `tol`.
pub fn refine_root(c: &[f32; 4], mut lo: f32, mut hi: f32, flo: f32, fhi: f32, tol: f32) -> f32 {
    let neg_lo = flo < 0.0;
    let mut x = madd(hi - lo, flo / (flo - fhi), lo);
    x = x.clamp(lo, hi);
    let mut dxold = hi - lo;
    let mut dx = dxold;
    let mut f = eval(c, x);
    let mut fp = eval_deriv(c, x);
    for _ in 0..CUBIC_MAX_ITERS {
        if f == 0.0 {
            break;
        }
        if (f < 0.0) == neg_lo {
            lo = x;
        } else {
            hi = x;
        }
        let out_of_bracket = madd(x - hi, fp, -f) * madd(x - lo, fp, -f) >= 0.0;
        let slow = (2.0 * f).abs() > (dxold * fp).abs();
        dxold = dx;
        if out_of_bracket || slow {
            dx = 0.5 * (hi - lo);
            x = lo + dx;
        } else {
            dx = f / fp;
            x -= dx;
        }
        if dx.abs() <= tol {
            break;
        }
        f = eval(c, x);
        fp = eval_deriv(c, x);
    }
    x
}

/// Running state of the sign walk over the monotone pieces. Brackets are recorded and refined
/// afterwards in one loop (the GLSL does so to keep one call site for lanes whose roots lie in
/// different pieces).
struct Walk {
    /// Sign of the last nonzero boundary value (0 before any).
    ps: f32,
    /// A zero boundary value is waiting for the next nonzero value to decide its direction.
    pending: bool,
    /// Position of the first zero of the pending run.
    zpos: f32,
    /// Crossings so far; those in `need` still hold a placeholder s.
    out: Crossings,
    /// Bit k: crossing k comes from the next unrefined bracket.
    need: u32,
    /// Brackets (lo, hi, f(lo), f(hi)), `nb` of them.
    br: [[f32; 4]; 3],
    nb: usize,
}

impl Walk {
    /// Piece (b0, b1), monotone, with f(b0) = v0 (already walked) and f(b1) = v1.
    fn piece(&mut self, b0: f32, v0: f32, b1: f32, v1: f32) {
        if v1 == 0.0 {
            if !self.pending {
                self.pending = true;
                self.zpos = b1;
            }
            return;
        }
        let sg = if v1 > 0.0 { 1.0 } else { -1.0 };
        if self.pending {
            if sg != self.ps {
                self.out.push(self.zpos, v1 > 0.0);
            }
            self.pending = false;
        } else if sg != self.ps {
            self.need |= 1 << self.out.n;
            self.br[self.nb] = [b0, b1, v0, v1];
            self.nb += 1;
            self.out.push(0.0, v1 > 0.0);
        }
        self.ps = sg;
    }
}

/// Sign-change crossings of f(s) = C3s³ + C2s² + C1s + C0′ on [0, L) (method.md §5), with
/// `ends` = [f(0), f(L)] from [`level_ends`]: [0, L] is split at the real roots of f′ into
/// monotone pieces (values at the critical points by Horner, snapped to 0 within rounding); a
/// piece whose end values have opposite signs holds one root, found by [`refine_root`] on the
/// original cubic. A zero at s = 0 belongs to this cell (the one the ray enters): it is a crossing
/// when the sign f takes after it differs from `before`, the sign (±1) of f just before the entry
/// point when the previous cell of the walk ended there (from [`exit_sign`]), or always when
/// `before` is 0 (unknown: no previous cell); a zero at s = L is left to the next cell. Both cells
/// read that shared point's value from the same trilerp of the shared corners, so a crossing on a
/// face is counted once, by the cell entered when that value is 0. Crossings closer than `CUBIC_MERGE_EPS·max(1, L)` are clustered and a cluster keeps its first
/// crossing only when it changes the sign (odd count). Never NaN/Inf: coefficients that are
/// non-finite (overflow in their formation) or L outside (0, [`CUBIC_MAX_L`]) give no crossings.
pub fn solve_crossings(cc: CellCubic, ends: [f32; 2], l: f32, before: f32) -> Crossings {
    let [c0, cl] = ends;
    let none = Crossings::default();
    if !(l > 0.0 && l < CUBIC_MAX_L) {
        return none;
    }
    // Zero, NaN or overflowed inputs: no crossings (a NaN or Inf makes the sum non-finite).
    let sum = c0.abs() + cl.abs() + cc.c1.abs() + cc.c2.abs() + cc.c3.abs();
    if !(sum > 0.0 && sum < f32::MAX) {
        return none;
    }
    let m = c0
        .abs()
        .max(cl.abs())
        .max(cc.c1.abs())
        .max(cc.c2.abs())
        .max(cc.c3.abs());
    let sc = pow2_scale(m);
    let c = [c0 * sc, cc.c1 * sc, cc.c2 * sc, cc.c3 * sc];
    // Critical points: roots of A s² + 2B s + C with A = 3C3, B = C2, C = C1.
    let a = 3.0 * c[3];
    let b = c[2];
    let cq = c[1];
    let w = a * cq;
    let disc = b.mul_add(b, -w) + (-a).mul_add(cq, w);
    let mut r1 = 0.0f32;
    let mut r2 = 0.0f32;
    if disc > 0.0 {
        let sq = disc.sqrt();
        let q = -(b + sq.copysign(b));
        let x1 = cq / q;
        r1 = if x1 > 0.0 && x1 < l { x1 } else { 0.0 };
        if a != 0.0 {
            let x2 = q / a;
            r2 = if x2 > 0.0 && x2 < l { x2 } else { 0.0 };
        }
    }
    let b1 = r1.min(r2);
    let b2 = r1.max(r2);
    let v0 = c[0];
    let v1 = crit_value(&c, b1);
    let v2 = crit_value(&c, b2);
    let v3 = cl * sc;
    // Fast exit: every boundary value strictly on one side.
    if (v0 > 0.0 && v1 > 0.0 && v2 > 0.0 && v3 > 0.0)
        || (v0 < 0.0 && v1 < 0.0 && v2 < 0.0 && v3 < 0.0)
    {
        return none;
    }
    let mut walk = Walk {
        ps: if v0 > 0.0 {
            1.0
        } else if v0 < 0.0 {
            -1.0
        } else {
            before
        },
        pending: v0 == 0.0,
        zpos: 0.0,
        out: none,
        need: 0,
        br: [[0.0; 4]; 3],
        nb: 0,
    };
    walk.piece(0.0, v0, b1, v1);
    walk.piece(b1, v1, b2, v2);
    walk.piece(b2, v2, l, v3);
    let tol = CUBIC_STEP_TOL * l.max(1.0);
    let mut r = [0.0f32; 3];
    for (x, b) in r.iter_mut().zip(&walk.br).take(walk.nb) {
        *x = refine_root(&c, b[0], b[1], b[2], b[3], tol);
    }
    let mut j = 0;
    for k in 0..3 {
        if walk.need & (1 << k) != 0 {
            walk.out.s[k] = r[j];
            j += 1;
        }
    }
    merge(walk.out, l)
}

/// The sign (±1, or 0 if unknown) of f just before s = L, for the next cell's `before` in
/// [`solve_crossings`]: after the last crossing its direction, else the sign at s = 0 (`f0`, or
/// `before` when f0 = 0). Crossings alternate and a merged cluster keeps its net direction, so this
/// is the sign the sign walk ends on.
pub fn exit_sign(x: &Crossings, f0: f32, before: f32) -> f32 {
    if x.n > 0 {
        if x.rising[x.n as usize - 1] {
            1.0
        } else {
            -1.0
        }
    } else if f0 > 0.0 {
        1.0
    } else if f0 < 0.0 {
        -1.0
    } else {
        before
    }
}

/// Cluster merge and the half-open clamp s < L. Crossings alternate in direction, so a cluster
/// (neighbours closer than `CUBIC_MERGE_EPS·max(1, L)`) changes the sign iff its count is odd; it then
/// keeps its first. With at most three crossings: 0 is kept unless it opens an even cluster {0,1};
/// 1 only when alone; 2 unless it joins 1.
fn merge(x: Crossings, l: f32) -> Crossings {
    let eps = CUBIC_MERGE_EPS * l.max(1.0);
    let gap01 = x.n >= 2 && x.s[1] - x.s[0] < eps;
    let gap12 = x.n >= 3 && x.s[2] - x.s[1] < eps;
    let keep = [
        x.n >= 1 && (!gap01 || gap12),
        x.n >= 2 && !gap01 && !gap12,
        x.n >= 3 && !gap12,
    ];
    let below = f32::from_bits(l.to_bits() - 1);
    let mut out = Crossings::default();
    for (k, _) in keep.iter().enumerate().filter(|(_, &kp)| kp) {
        out.push(x.s[k].min(below), x.rising[k]);
    }
    out
}

/// Convenience: coefficients and crossings for one (cell, ray, level), no previous cell.
pub fn crossings(corners: &[f32; 8], o: [f32; 3], d: [f32; 3], l: f32, tau: f32) -> Crossings {
    solve_crossings(
        cell_cubic(corners, o, d),
        level_ends(corners, o, d, l, tau),
        l,
        0.0,
    )
}
