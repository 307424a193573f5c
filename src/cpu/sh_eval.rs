//! Twin of `glsl/sh_eval.comp`: degree-2 SH basis and RGB per case.

use crate::math::sh::{sh_basis, sh_rgb};
use rayon::prelude::*;

/// `dirs`: 3 per case (unit); `coefs`: 27 per case; `out`: 12 per case (Y_0..Y_8, R, G, B).
pub fn sh_eval(dirs: &[f32], coefs: &[f32], out: &mut [f32]) {
    let n = dirs.len() / 3;
    assert_eq!(coefs.len(), 27 * n, "sh_eval: coefs length");
    assert_eq!(out.len(), 12 * n, "sh_eval: out length");
    out.par_chunks_exact_mut(12)
        .zip(dirs.par_chunks_exact(3))
        .zip(coefs.par_chunks_exact(27))
        .for_each(|((o, d), c)| {
            let y = sh_basis([d[0], d[1], d[2]]);
            o[0..9].copy_from_slice(&y);
            o[9..12].copy_from_slice(&sh_rgb(&y, c.try_into().expect("27 coefficients")));
        });
}
