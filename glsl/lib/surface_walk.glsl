// surface_walk.glsl — the stage-2 (αSurf) cell walk both surface kernels share (surface_fwd.comp,
// surface_train.comp; method.md §3.2, §5): DDA front to back from t = 0; with a skip structure
// (`blocks`, glsl/lib/surface_blocks.glsl) only over the ray's span inside the allocated box
// (surf_box_span), cells of mask-0 blocks are skipped and cells whose live bit is clear are
// passed over unread; cells with an unallocated corner and cells no level can cross (min/max
// culling, then segment culling on the ray's piece) are passed over.
// Rust twin: src/math/surface_walk.rs (CellWalk, WalkCell, WalkCounts: the same names, fields and
// steps; cell_walk_new is CellWalk::new, cell_walk_next its Iterator::next).
// Include AFTER the kernel's push-constant block `pc`, which must have the members n (uint),
// links (I32Buf) and delta (F32Buf): the grid the twin's `g` holds; define SURF_WALK_BLOCKS first
// as the U32Buf member holding the skip structure (the twin's SkipRef::words). Buffer references
// are read from `pc`, not held in the walk: a struct holding them makes spirv-opt emit invalid
// SPIR-V (a Function-storage pointer without AliasedPointer/RestrictPointer, as in plenoxel.glsl).
// Use:
//     CellWalk walk = cell_walk_new(og, dn, lv, nl, SkipRef(skipping, shift));
//     WalkCell cell;
//     while (cell_walk_next(walk, cell)) { ... the hits of cell ... }
//     ... walk.counts ...
#ifndef SURFACE_WALK_GLSL
#define SURFACE_WALK_GLSL

#include "surface.glsl"
#include "surface_blocks.glsl"

// A walk's skip structure (math::surface_blocks::SkipRef): the live-cell words, the nb³ block
// masks of 2^shift-cell blocks, then the allocated box, in SURF_WALK_BLOCKS. `used` false: no
// skip structure (the twin's None); SURF_WALK_BLOCKS and shift are then not read.
struct SkipRef {
    bool used;
    uint shift;
};

// What a walk counted (the first and last counters of both surface kernels' counts).
struct WalkCounts {
    uint cells;          // cells read (corners loaded)
    uint solves;         // cubic solves
    uint culled;         // solves culled (levels dropped by min/max or segment culling)
    uint blocks_skipped; // empty-space blocks skipped
};

// A cell of the walk that some level can cross: its DDA piece, corner links and δ values, the
// piece's entry/exit points q0/q1 in the cell, its cubic's C1..C3 (cc), and the levels that pass
// min/max and segment culling.
struct WalkCell {
    DdaPiece piece;
    int lk[8];
    float c[8];
    vec3 q0;
    vec3 q1;
    vec3 cc;
    uint mask;
};

struct CellWalk {
    float levels[SURF_MAX_LEVELS]; // the first n_levels are read
    uint n_levels;
    SkipRef blocks;
    vec3 og;
    vec3 dn;
    Dda w;
    // With a skip structure: the walk ends at the first piece entered at this t (the ray's exit
    // from the allocated box).
    float t_out;
    uint skipped;
    WalkCounts counts;
};

// A walk of ray og + t·dn (grid units, dn unit) over the grid of `pc` for the levels[0..n_levels).
CellWalk cell_walk_new(vec3 og, vec3 dn, float levels[SURF_MAX_LEVELS], uint n_levels,
                       SkipRef blocks) {
    uint n = pc.n;
    // With a skip structure, only the span inside the allocated box (SURF_BOX_WORDS after the
    // block masks).
    vec2 span = vec2(0.0, DDA_BIG);
    if (blocks.used) {
        uint nb = surf_blocks_per_axis(n, blocks.shift);
        uint bx = surf_live_words(n) + nb * nb * nb;
        span = surf_box_span(og, dn,
                             uvec3(SURF_WALK_BLOCKS.v[bx], SURF_WALK_BLOCKS.v[bx + 1u], SURF_WALK_BLOCKS.v[bx + 2u]),
                             uvec3(SURF_WALK_BLOCKS.v[bx + 3u], SURF_WALK_BLOCKS.v[bx + 4u], SURF_WALK_BLOCKS.v[bx + 5u]));
    }
    CellWalk walk;
    walk.levels = levels;
    walk.n_levels = n_levels;
    walk.blocks = blocks;
    walk.og = og;
    walk.dn = dn;
    // A miss (t_in ≥ t_out, or NaN) starts past every grid: the walk ends at once.
    walk.w = dda_init(og, dn, int(n), span.x < span.y ? span.x : DDA_BIG);
    walk.t_out = span.y;
    walk.skipped = SURF_NO_BLOCK;
    walk.counts = WalkCounts(0u, 0u, 0u, 0u);
    return walk;
}

// Walks on to the next cell some level can cross and returns true with it in `cell`, or returns
// false when the walk is over (every later call too). Kernels call it before solving: lanes then
// reach the cubic solver together instead of one solving while the others idle through empty
// cells. One loop with a break, no return inside it (dda_next: llvmpipe runs that faster).
bool cell_walk_next(inout CellWalk walk, out WalkCell cell) {
    uint n = pc.n;
    uint words = surf_live_words(n);
    bool found = false;
    while (dda_next(walk.w, cell.piece.cell, cell.piece.t0, cell.piece.t1)) {
        // Past the allocated box nothing can be hit (t0 only grows: every later call ends here
        // too).
        if (cell.piece.t0 >= walk.t_out) break;
        ivec3 l = cell.piece.cell;
        uint base = dda_cell_index(l, n);
        if (walk.blocks.used) {
            uint shift = walk.blocks.shift;
            uint nb = surf_blocks_per_axis(n, shift);
            uint bi = surf_block_index(l, nb, shift);
            uint word = SURF_WALK_BLOCKS.v[words + bi];
            if ((word & SURF_MASK_BITS) == 0u
                && surf_block_skip(walk.w, walk.dn, int(n), l, bi, walk.skipped, shift,
                                   word >> SURF_RADIUS_SHIFT)) {
                walk.counts.blocks_skipped++;
                continue;
            }
            if (!SURF_CELL_LIVE(SURF_WALK_BLOCKS, base)) continue;
        }
        walk.counts.cells++;
        cell_links(pc.links, uvec3(n), l, cell.lk);
        int lk_min = min(min(min(cell.lk[0], cell.lk[1]), min(cell.lk[2], cell.lk[3])),
                         min(min(cell.lk[4], cell.lk[5]), min(cell.lk[6], cell.lk[7])));
        if (lk_min < 0) continue;
        [[unroll]] for (int i = 0; i < 8; i++) cell.c[i] = pc.delta.v[cell.lk[i]];
        cell.mask = surf_level_mask(cell.c, walk.levels, walk.n_levels);
        if (cell.mask != 0u) {
            cell.q0 = surf_local(walk.w, walk.og, walk.dn, cell.piece.t0, l);
            cell.q1 = surf_local(walk.w, walk.og, walk.dn, cell.piece.t1, l);
            cell.cc = cubic_cell(cell.c, cell.q0, walk.dn);
            cell.mask = surf_segment_mask(cell.c, cell.cc, cell.q0, cell.q1,
                                          cell.piece.t1 - cell.piece.t0, walk.levels, cell.mask);
        }
        uint ns = uint(bitCount(cell.mask));
        walk.counts.solves += ns;
        walk.counts.culled += walk.n_levels - ns;
        if (cell.mask != 0u) {
            found = true;
            break;
        }
    }
    return found;
}

#endif
