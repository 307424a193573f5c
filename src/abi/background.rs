//! The host's side of the learned background colour ([`Background`], stepped by
//! `glsl/background_step.comp`).

use crate::abi::buffers::Background;

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
