//! Trilinear interpolation of a cell's 8 corner values, its analytic gradient and the trilinear
//! weights: the twin of `glsl/lib/trilerp.glsl` (same FMA nesting: z, then y, then x).
//! Corner order i = 4a + 2b + c (a = x bit, b = y bit, c = z bit), the paper's 000..111.

/// `a + t·(b − a)` as one FMA.
#[inline]
pub fn lerp_fma(a: f32, b: f32, t: f32) -> f32 {
    t.mul_add(b - a, a)
}

/// Trilinearly interpolated value at `p` ∈ [0,1]³.
pub fn trilerp(c: &[f32; 8], p: [f32; 3]) -> f32 {
    let m00 = lerp_fma(c[0], c[1], p[2]);
    let m01 = lerp_fma(c[2], c[3], p[2]);
    let m10 = lerp_fma(c[4], c[5], p[2]);
    let m11 = lerp_fma(c[6], c[7], p[2]);
    let n0 = lerp_fma(m00, m01, p[1]);
    let n1 = lerp_fma(m10, m11, p[1]);
    lerp_fma(n0, n1, p[0])
}

/// Value and gradient `∂/∂p` at `p`.
pub fn trilerp_grad(c: &[f32; 8], p: [f32; 3]) -> (f32, [f32; 3]) {
    let m00 = lerp_fma(c[0], c[1], p[2]);
    let m01 = lerp_fma(c[2], c[3], p[2]);
    let m10 = lerp_fma(c[4], c[5], p[2]);
    let m11 = lerp_fma(c[6], c[7], p[2]);
    let n0 = lerp_fma(m00, m01, p[1]);
    let n1 = lerp_fma(m10, m11, p[1]);
    let v = lerp_fma(n0, n1, p[0]);
    let gx = n1 - n0;
    let gy = lerp_fma(m01 - m00, m11 - m10, p[0]);
    let e0 = lerp_fma(c[1] - c[0], c[3] - c[2], p[1]);
    let e1 = lerp_fma(c[5] - c[4], c[7] - c[6], p[1]);
    let gz = lerp_fma(e0, e1, p[0]);
    (v, [gx, gy, gz])
}

/// The 8 weights `w_i(p)` with `trilerp(c, p) = Σ w_i c_i` (they sum to 1).
pub fn trilerp_weights(p: [f32; 3]) -> [f32; 8] {
    let q = [1.0 - p[0], 1.0 - p[1], 1.0 - p[2]];
    let xy = [q[0] * q[1], q[0] * p[1], p[0] * q[1], p[0] * p[1]];
    [
        xy[0] * q[2],
        xy[0] * p[2],
        xy[1] * q[2],
        xy[1] * p[2],
        xy[2] * q[2],
        xy[2] * p[2],
        xy[3] * q[2],
        xy[3] * p[2],
    ]
}

/// `∂w_i/∂s` of the weights above at `p` moving along the unit direction `d`.
pub fn trilerp_dwds(p: [f32; 3], d: [f32; 3]) -> [f32; 8] {
    let q = [1.0 - p[0], 1.0 - p[1], 1.0 - p[2]];
    std::array::from_fn(|i| {
        let (bx, by, bz) = (i >> 2 & 1, i >> 1 & 1, i & 1);
        let fx = if bx == 1 { p[0] } else { q[0] };
        let fy = if by == 1 { p[1] } else { q[1] };
        let fz = if bz == 1 { p[2] } else { q[2] };
        let sx = if bx == 1 { 1.0 } else { -1.0 };
        let sy = if by == 1 { 1.0 } else { -1.0 };
        let sz = if bz == 1 { 1.0 } else { -1.0 };
        sx * fy * fz * d[0] + fx * sy * fz * d[1] + fx * fy * sz * d[2]
    })
}

/// Links of the 8 corners of cell `l` in a grid of `res` vertices (x-major: slot
/// (x·ny + y)·nz + z), in the corner order above; < 0: unallocated.
#[inline]
pub fn cell_links(links: &[i32], res: [u32; 3], l: [i32; 3]) -> [i32; 8] {
    let (ny, nz) = (res[1] as usize, res[2] as usize);
    let base = (l[0] as usize * ny + l[1] as usize) * nz + l[2] as usize;
    let x = ny * nz;
    // One bounds check for the cell's span of slots instead of one per corner.
    let c = &links[base..base + x + nz + 2];
    [
        c[0],
        c[1],
        c[nz],
        c[nz + 1],
        c[x],
        c[x + 1],
        c[x + nz],
        c[x + nz + 1],
    ]
}
