//! Ray/box clipping and the DDA cell walk over an N³-vertex grid: the twin of `glsl/lib/dda.glsl`,
//! bit for bit (every plane crossing is `(k − o)·(1/d)`, one rounding per operation, the same
//! formula for the box faces and the interior planes). See that file for the tie rules
//! (method.md §5).

use super::madd::madd;

pub use crate::abi::consts::{DDA_BIG, DDA_HASH0, DDA_HUGE, DDA_SPLIT_MAX, DDA_TINY};

/// The float adjacent to `y > 0` on the side `up`.
fn adjacent(y: f32, up: bool) -> f32 {
    f32::from_bits(if up { y.to_bits() + 1 } else { y.to_bits() - 1 })
}

/// The exact product `a·b = p + q` (Dekker's product with Veltkamp's split, 4097 = 2^12 + 1):
/// multiplies and adds only, as in the GLSL, where `fma()` need not be fused.
fn two_prod(a: f32, b: f32) -> (f32, f32) {
    let p = a * b;
    let split = |x: f32| {
        let t = 4097.0 * x;
        let h = t - (t - x);
        (h, x - h)
    };
    let ((ah, al), (bh, bl)) = (split(a), split(b));
    (
        p,
        madd(al, bl, madd(al, bh, madd(ah, bl, madd(ah, bh, -p)))),
    )
}

/// `c − a·b`, exact when the result is representable and `a·b ≈ c`.
fn residual(c: f32, a: f32, b: f32) -> f32 {
    let (p, q) = two_prod(a, b);
    (c - p) - q
}

/// Correctly rounded `1/x` from a start `y0` within a few ulps of `1/|x|` (GLSL `dda_rcp`, which
/// starts from the device's division: Vulkan lets it be 2.5 ulp off; the twin starts from its own,
/// exact one). One Newton step makes it faithful; then the residual `1 − b·y` is exact for it and
/// its neighbour across `1/b`, and the nearer one has the smaller residual.
pub fn rcp_rn(x: f32, y0: f32) -> f32 {
    let b = x.abs();
    let e0 = residual(1.0, b, y0);
    let y = madd(y0, e0, y0);
    let e = residual(1.0, b, y);
    let z = adjacent(y, e > 0.0);
    let ez = residual(1.0, b, z);
    let r = if e != 0.0 && ez.abs() < e.abs() { z } else { y };
    if x < 0.0 {
        -r
    } else {
        r
    }
}

/// Correctly rounded `sqrt(x)` (x > 0, normal) from a start `s0` within a few ulps (GLSL
/// `dda_sqrt`). After one Newton step `r = x − s²` is exact; the neighbour `z = s + u` across
/// `sqrt(x)` is nearer iff `x` lies beyond the midpoint's square `s² + s·u + u²/4`, and as `r` and
/// `s·u` are multiples of `u²` that is the sign of `r − s·u` (> 0 for u > 0, ≤ 0 for u < 0).
pub fn sqrt_rn(x: f32, s0: f32) -> f32 {
    let r0 = residual(x, s0, s0);
    let s = madd(r0, 0.5 / s0, s0);
    let r = residual(x, s, s);
    let up = r > 0.0;
    let z = adjacent(s, up);
    let dm = madd(-s, z - s, r);
    let take = r != 0.0 && if up { dm > 0.0 } else { dm <= 0.0 };
    if take {
        z
    } else {
        s
    }
}

/// `d / |d|`, with a correctly rounded sqrt and reciprocal ([`sqrt_rn`], [`rcp_rn`]); `|d|²` as
/// plain products and sums (identical on every device).
pub fn ray_unit(d: [f32; 3]) -> [f32; 3] {
    let l2 = madd(d[2], d[2], madd(d[0], d[0], d[1] * d[1]));
    let s = sqrt_rn(l2, l2.sqrt());
    let r = rcp_rn(s, 1.0 / s);
    [d[0] * r, d[1] * r, d[2] * r]
}

/// Flushes tiny components to zero (applied to `o` and `d`: denormals read alike on every device).
pub fn dda_flush(d: [f32; 3]) -> [f32; 3] {
    d.map(|x| if x.abs() < DDA_TINY { 0.0 } else { x })
}

/// `1/d` per axis, correctly rounded ([`rcp_rn`]); 1 where `d == 0` (those axes never use it) or
/// `|d| ≥ DDA_HUGE` (those rays miss).
pub fn dda_inv(d: [f32; 3]) -> [f32; 3] {
    d.map(|x| {
        let x = if x == 0.0 || x.abs() >= DDA_HUGE {
            1.0
        } else {
            x
        };
        rcp_rn(x, 1.0 / x.abs())
    })
}

/// Slab clip of `o + t·d` against `[lo, hi]`: `[t_enter, t_exit]` with
/// `t_enter = max(slab entries, t_min)`. Hit iff `t_enter < t_exit` (touching an edge or corner in
/// one point misses). A zero direction component with `o` outside that slab misses; inside (faces
/// included) it adds no constraint. A zero direction vector, a NaN or infinite component in `o`
/// or `d`, or a component of `d` with magnitude ≥ [`DDA_HUGE`], misses.
pub fn ray_box(o: [f32; 3], d: [f32; 3], lo: [f32; 3], hi: [f32; 3], t_min: f32) -> [f32; 2] {
    let o = dda_flush(o);
    let d = dda_flush(d);
    let inv = dda_inv(d);
    let mut t0 = t_min;
    let mut t1 = DDA_BIG;
    for a in 0..3 {
        let ta = (lo[a] - o[a]) * inv[a];
        let tb = (hi[a] - o[a]) * inv[a];
        let inside = o[a] >= lo[a] && o[a] <= hi[a];
        let (tn, tf) = if d[a] == 0.0 {
            if inside {
                (-DDA_BIG, DDA_BIG)
            } else {
                (DDA_BIG, -DDA_BIG)
            }
        } else {
            (ta.min(tb), ta.max(tb))
        };
        t0 = t0.max(tn);
        t1 = t1.min(tf);
    }
    if t1 == DDA_BIG {
        t1 = -DDA_BIG;
    }
    let finite = o.iter().all(|x| x.abs() < DDA_BIG) && d.iter().all(|x| x.abs() < DDA_HUGE);
    if !finite {
        t0 = DDA_BIG;
        t1 = -DDA_BIG;
    }
    [t0, t1]
}

/// Walk state (GLSL `struct Dda`): start with [`dda_init`], then call [`dda_next`] (or iterate).
#[derive(Clone, Copy, Debug)]
pub struct Dda {
    /// Origin.
    pub o: [f32; 3],
    /// `1/d` (1 on zero axes, unused).
    pub inv: [f32; 3],
    /// Current cell.
    pub cell: [i32; 3],
    /// −1, 0 or +1 per axis.
    pub step: [i32; 3],
    /// t of the next plane crossing per axis (`DDA_BIG` on zero axes).
    pub t_next: [f32; 3],
    /// Entry t of the current cell.
    pub t: f32,
    /// Box exit.
    pub t_end: f32,
}

/// One cell of a walk and the t range `[t0, t1]` the ray spends in it (`t1 > t0`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DdaPiece {
    /// Cell index l ∈ [0, N−2]³.
    pub cell: [i32; 3],
    /// Entry t.
    pub t0: f32,
    /// Exit t.
    pub t1: f32,
}

fn sign_i(x: f32) -> i32 {
    if x > 0.0 {
        1
    } else if x < 0.0 {
        -1
    } else {
        0
    }
}

/// Starts a walk over the cells of an `n`³-vertex grid (clip box `[0, n−1]³`) from `t_min` on.
#[allow(clippy::neg_cmp_op_on_partial_ord)] // `!(a < b)` is true on NaN, as in the GLSL
pub fn dda_init(o: [f32; 3], d: [f32; 3], n: i32, t_min: f32) -> Dda {
    let o = dda_flush(o);
    let d = dda_flush(d);
    let hi = (n - 1) as f32;
    let [t, t_end] = ray_box(o, d, [0.0; 3], [hi; 3], t_min);
    let inv = dda_inv(d);
    let step = d.map(sign_i);
    let mut cell = [0i32; 3];
    let mut t_next = [DDA_BIG; 3];
    for a in 0..3 {
        let up = step[a].max(0);
        // Estimate from the entry point, then settle with the plane crossings themselves. The
        // entry point is o + (t·d as an exact product): no contraction changes it (when o and
        // t·d nearly cancel, a fused and an unfused o + t·d can lie several cells apart). Past
        // DDA_SPLIT_MAX the split would overflow: there the plain product.
        let (ph, pl) = if t.abs() < DDA_SPLIT_MAX {
            two_prod(t, d[a])
        } else {
            (t * d[a], 0.0)
        };
        let p = (o[a] + ph) + pl;
        let mut c = p.clamp(-1.0, n as f32).floor() as i32;
        let tn = ((c + up) as f32 - o[a]) * inv[a];
        c += i32::from(tn <= t) * step[a];
        let tp = ((c + 1 - up) as f32 - o[a]) * inv[a];
        c -= i32::from(tp > t) * step[a];
        cell[a] = c.clamp(0, n - 2);
        let tx = ((cell[a] + up) as f32 - o[a]) * inv[a];
        if d[a] != 0.0 {
            t_next[a] = tx;
        }
    }
    if !(t < t_end) {
        // Miss: a state whose first dda_next ends the walk at once.
        return Dda {
            o,
            inv,
            cell,
            step,
            t_next: [DDA_BIG; 3],
            t: -DDA_BIG,
            t_end: -DDA_BIG,
        };
    }
    Dda {
        o,
        inv,
        cell,
        step,
        t_next,
        t,
        t_end,
    }
}

/// Next cell of the walk, front to back; `None` when the walk is over. Same loop shape as the
/// GLSL (a do-while: past the end a call takes one zero-length step and returns `None`).
#[allow(clippy::neg_cmp_op_on_partial_ord)] // `!(a < b)` is true on NaN, as in the GLSL
pub fn dda_next(s: &mut Dda) -> Option<DdaPiece> {
    loop {
        let tm = s.t_next[0].min(s.t_next[1]).min(s.t_next[2].min(s.t_end));
        let piece = DdaPiece {
            cell: s.cell,
            t0: s.t,
            t1: tm,
        };
        for a in 0..3 {
            if s.t_next[a] == tm {
                s.cell[a] += s.step[a];
                s.t_next[a] = ((s.cell[a] + s.step[a].max(0)) as f32 - s.o[a]) * s.inv[a];
            }
        }
        s.t = tm;
        if tm > piece.t0 {
            return Some(piece);
        }
        if !(s.t < s.t_end) {
            return None;
        }
    }
}

impl Iterator for Dda {
    type Item = DdaPiece;
    fn next(&mut self) -> Option<DdaPiece> {
        dda_next(self)
    }
}

/// Linear index of a cell's (0,0,0) corner in the `n`³ vertex grid, x-major: `(x·n + y)·n + z`.
pub fn dda_cell_index(c: [i32; 3], n: u32) -> u32 {
    (c[0] as u32 * n + c[1] as u32) * n + c[2] as u32
}

/// Order-sensitive walk checksum (FNV-1a over cell indices), starting from [`DDA_HASH0`].
pub fn dda_hash(h: u32, idx: u32) -> u32 {
    (h ^ idx).wrapping_mul(16_777_619)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn walk(o: [f32; 3], d: [f32; 3], n: i32) -> Vec<([i32; 3], f32, f32)> {
        dda_init(o, d, n, 0.0)
            .map(|p| (p.cell, p.t0, p.t1))
            .collect()
    }

    /// From starts up to 3 ulps off (beyond Vulkan's 2.5-ulp division), rcp_rn and sqrt_rn return
    /// the correctly rounded result, over mantissas near 1, near 2, and random ones at many scales.
    #[test]
    fn reciprocal_and_sqrt_round_correctly_from_inexact_starts() {
        let nudge = |v: f32, k: i32| f32::from_bits((v.to_bits() as i64 + k as i64) as u32);
        let mut xs: Vec<f32> = Vec::new();
        for k in 0..2000u32 {
            xs.push(f32::from_bits(0x3f80_0000 + k));
            xs.push(f32::from_bits(0x3fff_ffff - k));
            xs.push(f32::from_bits(
                0x3f80_0000 + k.wrapping_mul(2_654_435_761) % 0x0080_0000,
            ));
        }
        let mut checked = 0;
        for &m in &xs {
            for e in [-90, -20, -1, 0, 1, 7, 25] {
                let x = m * 2f32.powi(e);
                let (want_r, want_s) = (1.0 / x, x.sqrt());
                for k in -3..=3 {
                    assert_eq!(rcp_rn(x, nudge(want_r, k)), want_r, "1/{x:e} from {k} ulp");
                    assert_eq!(rcp_rn(-x, nudge(want_r, k)), -want_r, "1/-{x:e}");
                    assert_eq!(
                        sqrt_rn(x, nudge(want_s, k)),
                        want_s,
                        "sqrt {x:e} from {k} ulp"
                    );
                    checked += 1;
                }
            }
        }
        assert_eq!(checked, 6000 * 7 * 7);
    }

    #[test]
    fn box_clip_rules() {
        let lo = [0.0; 3];
        let hi = [3.0; 3];
        // Zero component outside the slab: miss; on the face: no constraint.
        let [a, b] = ray_box([-1.0, 4.0, 1.0], [1.0, 0.0, 0.0], lo, hi, 0.0);
        assert!(a >= b);
        assert_eq!(
            ray_box([-1.0, 3.0, 1.0], [1.0, 0.0, 0.0], lo, hi, 0.0),
            [1.0, 4.0]
        );
        // Inside start: t_enter = t_min.
        assert_eq!(
            ray_box([1.0, 1.0, 1.0], [-1.0, 0.0, 0.0], lo, hi, 0.0),
            [0.0, 1.0]
        );
        // Corner graze: one point, a miss.
        let [a, b] = ray_box([-1.0, 2.0, 1.0], [1.0, 1.0, 0.0], lo, hi, 0.0);
        assert!(a >= b, "{a} {b}");
        // Zero direction: miss.
        let [a, b] = ray_box([1.0; 3], [0.0; 3], lo, hi, 0.0);
        assert!(a >= b);
        // A direction component at DDA_HUGE: miss; just below it: the walk's usual clip.
        let [a, b] = ray_box([1.0; 3], [DDA_HUGE, 1.0, 0.0], lo, hi, 0.0);
        assert!(a >= b);
        let [a, b] = ray_box([1.0; 3], [DDA_HUGE / 2.0, 0.0, 0.0], lo, hi, 0.0);
        assert!(a < b, "{a} {b}");
    }

    #[test]
    fn axis_and_diagonal_walks() {
        // Along +x on the outer face y = z = N−1: cells (i, N−2, N−2).
        let w = walk([-0.5, 3.0, 3.0], [1.0, 0.0, 0.0], 4);
        let cells: Vec<_> = w.iter().map(|p| p.0).collect();
        assert_eq!(cells, vec![[0, 2, 2], [1, 2, 2], [2, 2, 2]]);
        assert_eq!(w[0].1, 0.5);
        assert_eq!(w[2].2, 3.5);
        // Main diagonal through corners: all axes step at once.
        let w = walk([-1.0, -1.0, -1.0], [1.0, 1.0, 1.0], 4);
        let cells: Vec<_> = w.iter().map(|p| p.0).collect();
        assert_eq!(cells, vec![[0, 0, 0], [1, 1, 1], [2, 2, 2]]);
        // Negative direction from an integer start: the cell below.
        let w = walk([2.0, 1.5, 1.5], [-1.0, 0.0, 0.0], 4);
        let cells: Vec<_> = w.iter().map(|p| p.0).collect();
        assert_eq!(cells, vec![[1, 1, 1], [0, 1, 1]]);
    }
}
