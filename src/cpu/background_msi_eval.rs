//! Twin of `glsl/background_msi_eval.comp`: the background of each test ray and the table's
//! gradient.

use crate::abi::buffers::BackgroundSpheres;
use crate::math::atomic;
use crate::math::background_msi::{backward, composite};
use rayon::prelude::*;

/// `rays`: 6 floats per ray; `upstream`: dL/dB, 3 per ray; `out`: 4 per ray (B, T_L); `grad`
/// (the table's length) += dL/d(texel values).
pub fn background_msi_eval(
    s: &BackgroundSpheres,
    table: &[f32],
    rays: &[f32],
    upstream: &[f32],
    rgb: [f32; 3],
    out: &mut [f32],
    grad: &mut [f32],
) {
    let n = rays.len() / 6;
    assert_eq!(
        upstream.len(),
        3 * n,
        "background_msi_eval: upstream length"
    );
    assert_eq!(out.len(), 4 * n, "background_msi_eval: out length");
    let grad = atomic::as_atomic(grad);
    out.par_chunks_exact_mut(4)
        .zip(rays.par_chunks_exact(6))
        .zip(upstream.par_chunks_exact(3))
        .for_each(|((o, r), g)| {
            let (ro, rd) = ([r[0], r[1], r[2]], [r[3], r[4], r[5]]);
            let (b, t) = composite(s, table, ro, rd, rgb);
            o[..3].copy_from_slice(&b);
            o[3] = t;
            backward(s, table, grad, ro, rd, b, [g[0], g[1], g[2]]);
        });
}
