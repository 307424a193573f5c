//! Twin of `background_step.comp`: one RMSProp step of a learned background colour, projected
//! onto [0, 1] (the kernel says why).

use crate::abi::buffers::Background;
use crate::math::rmsprop::rmsprop_one;

/// Twin of `background_step.comp`: per channel the RMSProp update of `rmsprop_one`, then the
/// colour clamped to [0, 1]; the gradient cleared.
pub fn background_step(bg: &mut Background, lr: f32, beta: f32, eps: f32) {
    for ch in 0..3 {
        let (mut v, mut g, mut r) = (bg.rgb[ch], bg.grad[ch], bg.avg[ch]);
        rmsprop_one(&mut v, &mut g, &mut r, lr, beta, eps);
        bg.rgb[ch] = v.clamp(0.0, 1.0);
        bg.grad[ch] = g;
        bg.avg[ch] = r;
    }
}
