//! Twin of `glsl/surface_fwd.comp`: stage-2 (αSurf) forward rendering, one rayon task per ray,
//! the same DDA walk (`math::dda`) with the same block skipping (`math::surface_blocks`), per-cell
//! hits (`math::surface`) and compositing arithmetic.

use crate::abi::surface_grid::SurfaceGridRef;
use crate::math::cubic::{cell_cubic, CellCubic};
use crate::math::dda::{dda_cell_index, dda_init, dda_next, ray_unit, Dda, DdaPiece, DDA_BIG};
use crate::math::sh::sh_basis;
use crate::math::surface::{
    surf_alpha, surf_cell_hits, surf_gamma, surf_level_mask, surf_local, surf_ray,
    surf_segment_mask, FaceSigns, SurfOut, SURF_MAX_LEVELS,
};
use crate::math::surface_blocks::{
    surf_block_index, surf_block_skip, surf_blocks_per_axis, surf_box_span, surf_live_words,
    SkipRef, SURF_BOX_WORDS, SURF_MASK_BITS, SURF_NO_BLOCK, SURF_RADIUS_SHIFT,
};
use crate::math::trilerp::trilerp_weights;
use anyhow::{ensure, Result};
use rayon::prelude::*;

pub use crate::abi::buffers::SurfCounts;

/// What a [`CellWalk`] counted (the first and last counters of both surface kernels).
#[derive(Clone, Copy, Debug, Default)]
pub struct WalkCounts {
    /// Cells read (corners loaded).
    pub cells: u32,
    /// Cubic solves.
    pub solves: u32,
    /// Solves culled (levels dropped by min/max or segment culling).
    pub culled: u32,
    /// Empty-space blocks skipped.
    pub blocks_skipped: u32,
}

/// How rays map into the grid, the levels, truncation and early termination.
#[derive(Clone, Debug)]
pub struct SurfaceParams {
    /// grid = p·scale + offset (per axis).
    pub scale: [f32; 3],
    pub offset: [f32; 3],
    /// Level values τ_i (at most [`SURF_MAX_LEVELS`]).
    pub levels: Vec<f32>,
    /// Truncation parameter a: hits j ≥ a get γ = 0 (the ray stops there).
    pub a: f32,
    /// Stop once transmittance falls below this.
    pub stop_thresh: f32,
}

/// A cell of the walk that some level can cross: its DDA piece, corner links and δ values, the
/// piece's entry/exit points q0/q1 in the cell, its cubic's C1..C3, and the levels that pass
/// min/max and segment culling.
pub struct WalkCell {
    pub piece: DdaPiece,
    pub lk: [i32; 8],
    pub c: [f32; 8],
    pub q0: [f32; 3],
    pub q1: [f32; 3],
    pub cc: CellCubic,
    pub mask: u32,
}

/// The cell walk both surface kernels share: DDA front to back from t = 0; with a skip structure
/// (`blocks`, `cpu::surface_blocks::build_blocks`) only over the ray's span inside the allocated
/// box (`surf_box_span`), cells of mask-0 blocks are skipped and cells whose live bit is clear
/// are passed over unread; cells with an unallocated corner and cells no
/// level can cross (min/max culling, then segment culling on the ray's piece) are passed over.
pub struct CellWalk<'a> {
    g: &'a SurfaceGridRef<'a>,
    levels: &'a [f32],
    blocks: Option<SkipRef<'a>>,
    og: [f32; 3],
    dn: [f32; 3],
    w: Dda,
    /// With a skip structure: the walk ends at the first piece entered at this t (the ray's exit
    /// from the allocated box).
    t_out: f32,
    skipped: u32,
    pub counts: WalkCounts,
}

impl<'a> CellWalk<'a> {
    pub fn new(
        g: &'a SurfaceGridRef<'a>,
        og: [f32; 3],
        dn: [f32; 3],
        levels: &'a [f32],
        blocks: Option<SkipRef<'a>>,
    ) -> Self {
        // With a skip structure, only the span inside the allocated box (SURF_BOX_WORDS).
        let [t_in, t_out] = match blocks {
            Some(b) => surf_box_span(og, dn, &b.words[b.words.len() - SURF_BOX_WORDS..]),
            None => [0.0, DDA_BIG],
        };
        CellWalk {
            g,
            levels,
            blocks,
            og,
            dn,
            // A miss (t_in ≥ t_out, or NaN) starts past every grid: the walk ends at once.
            w: dda_init(
                og,
                dn,
                g.n as i32,
                if t_in < t_out { t_in } else { DDA_BIG },
            ),
            t_out,
            skipped: SURF_NO_BLOCK,
            counts: WalkCounts::default(),
        }
    }
}

impl Iterator for CellWalk<'_> {
    type Item = WalkCell;

    fn next(&mut self) -> Option<WalkCell> {
        let g = self.g;
        let n = g.n as usize;
        let (nz, nyz) = (n, n * n);
        let words = surf_live_words(g.n) as usize;
        while let Some(piece) = dda_next(&mut self.w) {
            // Past the allocated box nothing can be hit (t0 only grows: every later call ends
            // here too).
            if piece.t0 >= self.t_out {
                break;
            }
            let l = piece.cell;
            let base = dda_cell_index(l, g.n) as usize;
            if let Some(SkipRef { words: skip, shift }) = self.blocks {
                let nb = surf_blocks_per_axis(g.n, shift);
                let bi = surf_block_index(l, nb, shift);
                let word = skip[words + bi as usize];
                if word & SURF_MASK_BITS == 0
                    && surf_block_skip(
                        &mut self.w,
                        self.dn,
                        g.n as i32,
                        l,
                        bi,
                        &mut self.skipped,
                        shift,
                        word >> SURF_RADIUS_SHIFT,
                    )
                {
                    self.counts.blocks_skipped += 1;
                    continue;
                }
                if skip[base >> 5] & (1 << (base & 31)) == 0 {
                    continue;
                }
            }
            self.counts.cells += 1;
            let lk = [
                g.links[base],
                g.links[base + 1],
                g.links[base + nz],
                g.links[base + nz + 1],
                g.links[base + nyz],
                g.links[base + nyz + 1],
                g.links[base + nyz + nz],
                g.links[base + nyz + nz + 1],
            ];
            if lk.iter().any(|&k| k < 0) {
                continue;
            }
            let c = lk.map(|k| g.delta[k as usize]);
            let mut mask = surf_level_mask(&c, self.levels);
            let (mut q0, mut q1, mut cc) = ([0.0; 3], [0.0; 3], CellCubic::default());
            if mask != 0 {
                q0 = surf_local(&self.w, self.og, self.dn, piece.t0, l);
                q1 = surf_local(&self.w, self.og, self.dn, piece.t1, l);
                cc = cell_cubic(&c, q0, self.dn);
                let len = piece.t1 - piece.t0;
                mask = surf_segment_mask(&c, cc, q0, q1, len, self.levels, mask);
            }
            self.counts.solves += mask.count_ones();
            self.counts.culled += self.levels.len() as u32 - mask.count_ones();
            if mask != 0 {
                return Some(WalkCell {
                    piece,
                    lk,
                    c,
                    q0,
                    q1,
                    cc,
                    mask,
                });
            }
        }
        None
    }
}

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
        for &s in hits.as_slice() {
            if j as f32 >= p.a {
                cnt.cut += 1;
                break 'walk;
            }
            let pos = std::array::from_fn(|k| (q0[k] + s * dn[k]).clamp(0.0, 1.0));
            let wt = trilerp_weights(pos);
            let mut sa = 0.0f32;
            for i in 0..8 {
                sa += wt[i] * g.opacity[lk[i] as usize];
            }
            let at = surf_alpha(sa) * surf_gamma(p.a, j);
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
            cnt.hits += 1;
            if t_acc < p.stop_thresh {
                break 'walk;
            }
        }
    }
    let w = walk.counts;
    (cnt.cells, cnt.solves, cnt.culled, cnt.blocks_skipped) =
        (w.cells, w.solves, w.culled, w.blocks_skipped);
    (
        SurfOut {
            rgb: color.map(|c| c + t_acc),
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
