//! Real spherical harmonics of degree 2 and the SH colour (method.md §1): the twin of
//! `glsl/lib/sh.glsl`. Coefficients per vertex: 27 floats `[R0..R8, G0..G8, B0..B8]`.

pub use crate::abi::consts::{SH_C0, SH_C1, SH_C2, SH_C3, SH_C4};

/// The 9 basis values at the unit direction `d`.
pub fn sh_basis(d: [f32; 3]) -> [f32; 9] {
    let [x, y, z] = d;
    let (xx, yy, zz) = (x * x, y * y, z * z);
    [
        SH_C0,
        -SH_C1 * y,
        SH_C1 * z,
        -SH_C1 * x,
        SH_C2 * (x * y),
        -SH_C2 * (y * z),
        SH_C3 * ((2.0 * zz - xx) - yy),
        -SH_C2 * (x * z),
        SH_C4 * (xx - yy),
    ]
}

/// `Σ_k y_k·c_k` (FMA chain in k order).
pub fn sh_dot(y: &[f32; 9], c: &[f32]) -> f32 {
    let mut acc = y[0] * c[0];
    for k in 1..9 {
        acc = y[k].mul_add(c[k], acc);
    }
    acc
}

/// `max(0, Σ_k y_k·c_k + 0.5)`: one colour channel from its 9 coefficients.
pub fn sh_channel(y: &[f32; 9], c: &[f32]) -> f32 {
    (sh_dot(y, c) + 0.5).max(0.0)
}

/// RGB from the basis values and 27 coefficients `[R0..R8, G0..G8, B0..B8]`.
pub fn sh_rgb(y: &[f32; 9], coefs: &[f32; 27]) -> [f32; 3] {
    [
        sh_channel(y, &coefs[0..9]),
        sh_channel(y, &coefs[9..18]),
        sh_channel(y, &coefs[18..27]),
    ]
}
