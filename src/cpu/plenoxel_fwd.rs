//! Twin of `glsl/plenoxel_fwd.comp`: one rayon task per ray, the forward march of
//! `math::plenoxel`.

use crate::abi::consts::REPLAY;
use crate::math::background_msi::BackgroundView;
use crate::math::plenoxel::{forward, march_init, ray, GridRef, MarchParams, PlenoxelCounts};
use crate::math::sh::sh_basis;
use rayon::prelude::*;

/// Twin of `plenoxel_fwd.comp`: rgb per ray (composited on what `bg` puts behind it) and the
/// summed sample counts.
pub fn render(
    g: &GridRef,
    rays: &[f32],
    mp: &MarchParams,
    bg: &BackgroundView,
) -> (Vec<f32>, PlenoxelCounts) {
    let n = rays.len() / 6;
    let out: Vec<([f32; 3], PlenoxelCounts)> = (0..n)
        .into_par_iter()
        .map(|r| {
            let (ro, rd) = ray(rays, r);
            let mut counts = PlenoxelCounts::default();
            let (color, t_acc) = match march_init(ro, rd, mp.scale, mp.offset, g.res) {
                Some(m) => forward(
                    g,
                    &m,
                    &sh_basis(rd),
                    mp.stop_thresh,
                    &mut counts,
                    &mut [0; REPLAY],
                ),
                None => ([0.0; 3], 1.0),
            };
            let (behind, _) = bg.behind(ro, rd);
            (
                std::array::from_fn(|ch| color[ch] + t_acc * behind[ch]),
                counts,
            )
        })
        .collect();
    let counts = out.iter().fold(PlenoxelCounts::default(), |a, o| a + o.1);
    (out.into_iter().flat_map(|o| o.0).collect(), counts)
}
