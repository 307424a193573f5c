//! Twin of `glsl/trilerp_eval.comp`: trilinear value, gradient and weights per case.

use crate::math::trilerp::{trilerp_grad, trilerp_weights};
use rayon::prelude::*;

/// `corners`: 8 per case; `points`: 3 per case; `out`: 12 per case (value, ∂x, ∂y, ∂z, 8 weights).
pub fn trilerp_eval(corners: &[f32], points: &[f32], out: &mut [f32]) {
    let n = corners.len() / 8;
    assert_eq!(points.len(), 3 * n, "trilerp_eval: points length");
    assert_eq!(out.len(), 12 * n, "trilerp_eval: out length");
    out.par_chunks_exact_mut(12)
        .zip(corners.par_chunks_exact(8))
        .zip(points.par_chunks_exact(3))
        .for_each(|((o, c), p)| {
            let c: &[f32; 8] = c.try_into().expect("8 corners");
            let p = [p[0], p[1], p[2]];
            let (v, g) = trilerp_grad(c, p);
            o[0] = v;
            o[1..4].copy_from_slice(&g);
            o[4..12].copy_from_slice(&trilerp_weights(p));
        });
}
