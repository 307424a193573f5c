// surface_blocks.glsl — coarse empty-space skipping for the stage-2 (αSurf) cell walk
// (method.md §3.2, §5). Rust twin: src/math/surface_blocks.rs (same operations in the same order).
//
// A block is 8³ cells: block b (per axis) covers the cells [8b, 8b+8) ∩ [0, n−2], i.e. the vertex
// range [8b, min(8b+8, n−1)]; there are nb = ceil((n−1)/8) blocks per axis, indexed x-major
// (bx·nb + by)·nb + bz. Its level mask (kernel surface_blocks) has bit i set iff τ_i lies within
// [bmin − margin, bmax + margin], bmin/bmax the min/max of δ over the block's ALLOCATED vertices;
// a block without any allocated vertex gets mask 0. A cell the walk can solve has all 8 corners
// allocated and inside its block's vertex range, so its min/max culling range lies within the
// block's: a block with mask 0 holds no hit (margin ≥ 0; min/max are exact, no rounding).
//
// Skipping in a walk loop (surface_fwd.comp is the reference use):
//     uint skipped = SURF_NO_BLOCK;
//     while (dda_next(w, l, t0, t1)) {
//         uint bi = surf_block_index(l, nb);
//         if (<block mask of bi> == 0u && surf_block_skip(w, og, dn, int(n), l, t0, bi, skipped))
//             continue;   // w now restarts at the block's exit
//         ... the cell as before ...
//     }
// og, dn: the same origin and direction the walk was started with (dda_init(og, dn, n, ·)).
// Exactness: the block exit t_exit = ray_box(og, dn, block box, t0).y is the far-plane crossing
// (k − o)·(1/d) with dda.glsl's own formula, hence bit-identical to the t at which the continuous
// walk leaves the block; dda_init(og, dn, n, t_exit) settles the cell with those same crossings
// and recomputes t_next with the same formula, so the pieces (cell, t0, t1) after the block are
// exactly the ones the continuous walk would produce. Should rounding ever settle the restart back
// inside the skipped block, `skipped` makes the walk go through it cell by cell (never a loop).
// The masks must describe the current δ: rebuild them after every δ update (or use a margin that
// bounds the drift since they were built).
#ifndef SURFACE_BLOCKS_GLSL
#define SURFACE_BLOCKS_GLSL

#include "dda.glsl"

// Block edge in cells, and its log2.
const int SURF_BLOCK = 8;
const int SURF_BLOCK_SHIFT = 3;
// "No block skipped yet" (an index no block has).
const uint SURF_NO_BLOCK = 0xffffffffu;

// Blocks per axis of an n³-vertex grid (n ≥ 2): ceil((n − 1)/8).
uint surf_blocks_per_axis(uint n) {
    return (n + uint(SURF_BLOCK - 2)) >> SURF_BLOCK_SHIFT;
}

// Linear index of the block holding cell l.
uint surf_block_index(ivec3 l, uint nb) {
    uvec3 b = uvec3(l >> SURF_BLOCK_SHIFT);
    return (b.x * nb + b.y) * nb + b.z;
}

// Vertex box [lo, hi] of the block holding cell l (grid of n³ vertices).
void surf_block_box(ivec3 l, int n, out vec3 lo, out vec3 hi) {
    ivec3 b0 = (l >> SURF_BLOCK_SHIFT) << SURF_BLOCK_SHIFT;
    lo = vec3(b0);
    hi = vec3(min(b0 + SURF_BLOCK, ivec3(n - 1)));
}

// Start of a block's δ range scan (the largest float): bmin = SURF_BLOCK_BIG and
// bmax = −SURF_BLOCK_BIG, an empty range (bmin > bmax) that stays so without allocated vertices.
const float SURF_BLOCK_BIG = 3.402823466e38;

// Block level mask from the block's δ range: bit i (i < nl) set iff
// bmin − margin ≤ lv[i] ≤ bmax + margin; 0 for an empty range (no allocated vertex).
uint surf_block_mask(float bmin, float bmax, float margin, float lv[8], uint nl) {
    precise float lo = bmin - margin;
    precise float hi = bmax + margin;
    bool has = bmin <= bmax;
    uint m = 0u;
    for (uint i = 0u; i < 8u; i++) {
        if (has && i < nl && lo <= lv[i] && lv[i] <= hi) m |= 1u << i;
    }
    return m;
}

// Called when the walk w (started as dda_init(og, dn, n, ·)) has just produced the piece of cell l
// entered at t0, whose block bi has mask 0: unless bi is the block skipped last, restarts w at the
// block's exit, records bi in `skipped` and returns true (the caller drops the cell and continues
// with dda_next); returns false (walk the cell as usual) when bi == skipped.
bool surf_block_skip(inout Dda w, vec3 og, vec3 dn, int n, ivec3 l, float t0, uint bi,
                     inout uint skipped) {
    if (bi == skipped) return false;
    vec3 lo, hi;
    surf_block_box(l, n, lo, hi);
    float t_exit = ray_box(og, dn, lo, hi, t0).y;
    w = dda_init(og, dn, n, t_exit);
    skipped = bi;
    return true;
}

#endif
