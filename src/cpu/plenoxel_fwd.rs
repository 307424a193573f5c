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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::check::plenoxel::test_scene;
    use crate::cpu::occupancy::occupancy;
    use crate::math::plenoxel::{OCC_SHIFT, OCC_SHIFT_CPU};
    use crate::plenoxel::march_params;

    /// Skipping passes over only samples with σ ≤ SIGMA_EPS: whatever the block edge (the
    /// kernels', the CPU twins', one cell, or no block ever empty), the same colours to the bit,
    /// the same samples shaded, and the same samples walked past (evaluated empty or skipped).
    #[test]
    fn the_occupancy_block_edge_changes_no_result() {
        let (g, rays, _) = test_scene(5, 40, 4000);
        let mp = march_params(&g, 1e-4);
        let bg = BackgroundView::new([1.0, 0.5, 0.0], None);
        let run = |occ: &[u32], occ_shift: u32| {
            let view = GridRef {
                res: g.res,
                links: &g.links,
                density: &g.density,
                sh: &g.sh,
                occ,
                occ_shift,
            };
            render(&view, &rays, &mp, &bg)
        };
        let every_block = vec![1u32; occupancy(&g.links, &g.density, g.res, 0).len()];
        let (want, wc) = run(&every_block, 0);
        assert_eq!(wc.skipped, 0);
        assert!(wc.empty > 0 && wc.shaded > 0);
        for shift in [0, OCC_SHIFT_CPU, OCC_SHIFT] {
            let occ = occupancy(&g.links, &g.density, g.res, shift);
            let (got, c) = run(&occ, shift);
            assert!(c.skipped > 0, "shift {shift}: nothing skipped");
            assert_eq!(
                got.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                want.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                "shift {shift}"
            );
            assert_eq!(c.shaded, wc.shaded, "shift {shift}");
            assert_eq!(c.empty + c.skipped, wc.empty, "shift {shift}");
        }
    }
}
