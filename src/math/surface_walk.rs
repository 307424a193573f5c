//! The stage-2 (αSurf) cell walk both surface kernels share: the twin of
//! `glsl/lib/surface_walk.glsl` (the same names, fields and steps: `cell_walk_new` is
//! [`CellWalk::new`], `cell_walk_next` its [`Iterator::next`]).

use crate::abi::surface_grid::SurfaceGridRef;
use crate::math::cubic::{cell_cubic, CellCubic};
use crate::math::dda::{dda_cell_index, dda_init, dda_next, Dda, DdaPiece, DDA_BIG};
use crate::math::surface::{surf_level_mask, surf_local, surf_segment_mask};
use crate::math::surface_blocks::{
    surf_block_index, surf_block_skip, surf_blocks_per_axis, surf_box_span, surf_live_words,
    SkipRef, SURF_BOX_WORDS, SURF_MASK_BITS, SURF_NO_BLOCK, SURF_RADIUS_SHIFT,
};
use crate::math::trilerp::cell_links;

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
            let lk = cell_links(g.links, [g.n; 3], l);
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
