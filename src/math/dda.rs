//! Ray/box clipping and the DDA cell walk over an N³-vertex grid: the twin of `glsl/lib/dda.glsl`,
//! bit for bit (every plane crossing is `(k − o)·(1/d)`, one rounding per operation, the same
//! formula for the box faces and the interior planes). See that file for the tie rules
//! (method.md §5).

/// Stands for infinity (no NaN from 0·inf anywhere).
pub const DDA_BIG: f32 = f32::MAX;
/// Components of `o` and `d` with magnitude < `DDA_TINY` count as zero.
pub const DDA_TINY: f32 = 1e-30;
/// Initial value of the walk checksum ([`dda_hash`]).
pub const DDA_HASH0: u32 = 2_166_136_261;

/// `d / |d|`.
pub fn ray_unit(d: [f32; 3]) -> [f32; 3] {
    let l2 = d[2].mul_add(d[2], d[1].mul_add(d[1], d[0] * d[0]));
    let r = 1.0 / l2.sqrt();
    [d[0] * r, d[1] * r, d[2] * r]
}

/// Flushes tiny components to zero (applied to `o` and `d`: denormals read alike on every device).
pub fn dda_flush(d: [f32; 3]) -> [f32; 3] {
    d.map(|x| if x.abs() < DDA_TINY { 0.0 } else { x })
}

/// `1/d` per axis, 1 where `d == 0` (those axes never use it).
pub fn dda_inv(d: [f32; 3]) -> [f32; 3] {
    d.map(|x| 1.0 / if x == 0.0 { 1.0 } else { x })
}

/// Slab clip of `o + t·d` against `[lo, hi]`: `[t_enter, t_exit]` with
/// `t_enter = max(slab entries, t_min)`. Hit iff `t_enter < t_exit` (touching an edge or corner in
/// one point misses). A zero direction component with `o` outside that slab misses; inside (faces
/// included) it adds no constraint. A zero direction vector, or a NaN or infinite component in
/// `o` or `d`, misses.
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
    let finite = o.iter().chain(&d).all(|x| x.abs() < DDA_BIG);
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
        // Estimate from the entry point, then settle with the plane crossings themselves.
        let p = o[a] + t * d[a];
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
