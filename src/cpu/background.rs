//! Twin of `background_step.comp`: one RMSProp step of a learned background colour, projected
//! onto [0, 1] (the kernel says why).

use super::rmsprop_one;
pub use crate::abi::buffers::Background;

impl Background {
    /// A background of colour `rgb`, learned (its gradient accumulated and stepped) or fixed.
    pub fn new(rgb: [f32; 3], learn: bool) -> Self {
        Background {
            rgb,
            learn: u32::from(learn),
            ..Default::default()
        }
    }

    /// Whether the training passes accumulate its gradient.
    pub fn learned(&self) -> bool {
        self.learn != 0
    }
}

/// Twin of `background_step.comp`: per channel the RMSProp update of `rmsprop_one`, then the
/// colour clamped to [0, 1]; the gradient cleared.
pub fn step(bg: &mut Background, lr: f32, beta: f32, eps: f32) {
    for ch in 0..3 {
        let (mut v, mut g, mut r) = (bg.rgb[ch], bg.grad[ch], bg.avg[ch]);
        rmsprop_one(&mut v, &mut g, &mut r, lr, beta, eps);
        bg.rgb[ch] = v.clamp(0.0, 1.0);
        bg.grad[ch] = g;
        bg.avg[ch] = r;
    }
}
