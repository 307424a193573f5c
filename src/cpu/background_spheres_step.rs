//! Twin of `background_spheres_step.comp`: one RMSProp step of a background's sphere texels.

use crate::math::background_msi::SphereTable;
use crate::math::background_msi::TEXEL;
use crate::math::rmsprop::rmsprop_one;

/// Twin of `background_spheres_step.comp`: the RMSProp update of `rmsprop_one` for every texel
/// value with a nonzero gradient (σ at `lr_sigma`, the colour at `lr_colour`; values no ray
/// reached keep their running average, as svox2's sparse step), the gradient cleared.
pub fn background_spheres_step(
    s: &mut SphereTable,
    grad: &mut [f32],
    lr_sigma: f32,
    lr_colour: f32,
    beta: f32,
    eps: f32,
) {
    for (i, ((v, g), r)) in s
        .table
        .iter_mut()
        .zip(grad.iter_mut())
        .zip(&mut s.avg)
        .enumerate()
    {
        if *g != 0.0 {
            let lr = if i % TEXEL == 0 { lr_sigma } else { lr_colour };
            rmsprop_one(v, g, r, lr, beta, eps);
        }
    }
}
