//! Twin of `glsl/rmsprop.comp`.

use rayon::prelude::*;

/// RMSProp on touched entries (g ≠ 0), clearing the gradient: r ← (r == 0 ? g² : βr + (1 − β)g²);
/// θ ← θ − lr·g/(√r + ε); g ← 0.
pub fn rmsprop(
    param: &mut [f32],
    grad: &mut [f32],
    state: &mut [f32],
    lr: f32,
    beta: f32,
    eps: f32,
) {
    param
        .par_iter_mut()
        .zip(grad.par_iter_mut())
        .zip(state.par_iter_mut())
        .for_each(|((p, g), r)| {
            if *g == 0.0 {
                return;
            }
            let g2 = *g * *g;
            let rn = if *r == 0.0 {
                g2
            } else {
                beta * *r + (1.0 - beta) * g2
            };
            *r = rn;
            *p -= lr * *g / (rn.sqrt() + eps);
            *g = 0.0;
        });
}
