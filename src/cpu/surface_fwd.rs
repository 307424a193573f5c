//! Twin of `glsl/surface_fwd.comp`: stage-2 (αSurf) forward rendering, one rayon task per ray,
//! the same cell walk (`math::surface_walk`, with the block skipping of `math::surface_blocks`),
//! per-cell hits (`math::surface`) and compositing arithmetic.

use crate::abi::consts::SURF_PASS_MIN_T;
use crate::abi::surface_grid::SurfaceGridRef;
use crate::math::dda::ray_unit;
use crate::math::sh::sh_basis;
use crate::math::surface::SurfaceParams;
use crate::math::surface::{
    surf_alpha, surf_cell_hits, surf_gamma, surf_ray, FaceSigns, RayCount, SurfOut, SURF_MAX_LEVELS,
};
use crate::math::surface_blocks::{surf_blocks_per_axis, surf_live_words, SkipRef, SURF_BOX_WORDS};
use crate::math::surface_walk::CellWalk;
use crate::math::trilerp::trilerp_weights;
use anyhow::{ensure, Result};
use rayon::prelude::*;

pub use crate::abi::buffers::SurfCounts;

/// One ray: its output and counters. `blocks`: the skip structure of `g` for `p.levels`
/// (`cpu::surface_blocks::build_blocks`: live-cell bits and block masks); `None` walks every cell.
pub fn render_ray(
    g: &SurfaceGridRef,
    ro: [f32; 3],
    rd: [f32; 3],
    p: &SurfaceParams,
    blocks: Option<SkipRef>,
) -> (SurfOut, SurfCounts) {
    let levels = &p.levels[..p.levels.len().min(SURF_MAX_LEVELS)];
    let (og, dn) = surf_ray(ro, rd, p.scale, p.offset);
    let y = sh_basis(ray_unit(rd));
    let mut color = [0f32; 3];
    let mut t_acc = 1.0f32;
    let mut j = 0u32;
    // The truncation count: j itself, or per structure the hits since the ray entered level 0.
    let a = p.truncation.a;
    let mut rc = RayCount::new(p.truncation);
    let mut cnt = SurfCounts::default();
    let mut walk = CellWalk::new(g, og, dn, levels, blocks);
    let mut face = FaceSigns::default();
    'walk: for cell in walk.by_ref() {
        let (piece, c, q0, lk) = (cell.piece, cell.c, cell.q0, cell.lk);
        let len = piece.t1 - piece.t0;
        let before = face.before(piece.t0);
        let hits = surf_cell_hits(&c, cell.cc, q0, cell.q1, len, levels, cell.mask, before);
        face = FaceSigns {
            t: piece.t1,
            ..hits.exit
        };
        let mut outer = hits.outer;
        for &s in hits.as_slice() {
            rc.restart(s, &mut outer);
            if rc.truncated() {
                cnt.cut += 1;
                if rc.passes_over() && t_acc >= SURF_PASS_MIN_T {
                    continue;
                }
                break 'walk;
            }
            let pos = std::array::from_fn(|k| (q0[k] + s * dn[k]).clamp(0.0, 1.0));
            let wt = trilerp_weights(pos);
            let mut sa = 0.0f32;
            for i in 0..8 {
                sa += wt[i] * g.opacity[lk[i] as usize];
            }
            let at = surf_alpha(sa) * surf_gamma(a, rc.k);
            let mut sh = [0f32; 27];
            for i in 0..8 {
                let row = &g.sh[lk[i] as usize * 27..lk[i] as usize * 27 + 27];
                for k in 0..27 {
                    sh[k] += wt[i] * row[k];
                }
            }
            let wj = t_acc * at;
            for ch in 0..3 {
                let mut acc = 0.5f32;
                for k in 0..9 {
                    acc += y[k] * sh[ch * 9 + k];
                }
                color[ch] += wj * acc.max(0.0);
            }
            t_acc *= 1.0 - at;
            j += 1;
            rc.k += 1;
            cnt.hits += 1;
            if t_acc < p.stop_thresh {
                break 'walk;
            }
        }
    }
    let w = walk.counts;
    let (behind, _) = p.behind().behind(ro, rd);
    (cnt.cells, cnt.solves, cnt.culled, cnt.blocks_skipped) =
        (w.cells, w.solves, w.culled, w.blocks_skipped);
    (
        SurfOut {
            rgb: std::array::from_fn(|ch| color[ch] + t_acc * behind[ch]),
            transmittance: t_acc,
            hits: j,
        },
        cnt,
    )
}

/// The block-mask count must match the grid (`nb`³, `math::surface_blocks`).
pub fn validate_blocks(g: &SurfaceGridRef, blocks: Option<SkipRef>) -> Result<()> {
    if let Some(SkipRef { words: b, shift }) = blocks {
        ensure!(
            (1..=8).contains(&shift),
            "skip structure with 2^{shift}-cell blocks (want 2 to 256 cells)"
        );
        let nb = surf_blocks_per_axis(g.n, shift) as usize;
        let words = surf_live_words(g.n) as usize;
        ensure!(
            b.len() == words + nb * nb * nb + SURF_BOX_WORDS,
            "skip structure of {} words, want {words} live-cell words + {nb}³ block masks + \
             {SURF_BOX_WORDS} box words for n = {}",
            b.len(),
            g.n
        );
    }
    Ok(())
}

/// Checks shared by both surface renderers: grid arrays, level count, ray layout.
pub fn validate_inputs(g: &SurfaceGridRef, rays: &[f32], p: &SurfaceParams) -> Result<()> {
    g.validate()?;
    ensure!(
        p.levels.len() <= SURF_MAX_LEVELS,
        "at most {SURF_MAX_LEVELS} levels, got {}",
        p.levels.len()
    );
    ensure!(rays.len().is_multiple_of(6), "rays must be 6 floats each");
    Ok(())
}

/// Twin of `surface_fwd.comp`: one output per ray (`rays`: 6 floats each, scene origin and
/// direction) and the summed counters. `blocks` as in [`render_ray`] (`None`: `block_skip` = 0).
pub fn render(
    g: &SurfaceGridRef,
    rays: &[f32],
    p: &SurfaceParams,
    blocks: Option<SkipRef>,
) -> Result<(Vec<SurfOut>, SurfCounts)> {
    validate_inputs(g, rays, p)?;
    validate_blocks(g, blocks)?;
    let out: Vec<(SurfOut, SurfCounts)> = rays
        .par_chunks_exact(6)
        .map(|r| render_ray(g, [r[0], r[1], r[2]], [r[3], r[4], r[5]], p, blocks))
        .collect();
    let counts = out.iter().fold(SurfCounts::default(), |a, (_, c)| a + *c);
    Ok((out.into_iter().map(|o| o.0).collect(), counts))
}
