// surface_blocks.glsl — coarse empty-space skipping for the stage-2 (αSurf) cell walk
// (method.md §3.2, §5). Rust twin: src/math/surface_blocks.rs (same operations in the same order).
//
// A block is B³ cells, B = 2^shift (the backend's choice, passed to the kernels: Rust
// SURF_BLOCK_SHIFT_CPU / _VULKAN): block b (per axis) covers the cells [Bb, Bb+B) ∩ [0, n−2],
// i.e. the vertex range [Bb, min(Bb+B, n−1)]; there are nb = ceil((n−1)/B) blocks per axis,
// indexed x-major (bx·nb + by)·nb + bz. Its level mask (kernel surface_blocks) has bit i set iff τ_i lies within
// [bmin − margin, bmax + margin], bmin/bmax the min/max of δ over the block's ALLOCATED vertices;
// a block without any allocated vertex gets mask 0. A cell the walk can solve has all 8 corners
// allocated and inside its block's vertex range, so its min/max culling range lies within the
// block's: a block with mask 0 holds no hit (margin ≥ 0; min/max are exact, no rounding).
//
// A block word holds the level mask in its low SURF_MASK_BITS and, for a mask-0 block, its empty
// radius r from bit SURF_RADIUS_SHIFT on (kernel surface_block_radius): every block within
// Chebyshev distance r of it (inside the grid) has mask 0 too, so the walk may jump to the exit of
// that cube of blocks, which is a box of the same kind (integer planes, no hit inside).
//
// Skipping in a walk loop (cell_walk_next in surface_walk.glsl is the reference use):
//     uint skipped = SURF_NO_BLOCK;
//     while (dda_next(w, l, t0, t1)) {
//         uint bi = surf_block_index(l, nb, shift);
//         uint word = <block word of bi>;
//         if ((word & SURF_MASK_BITS) == 0u
//             && surf_block_skip(w, dn, int(n), l, bi, skipped, shift, word >> SURF_RADIUS_SHIFT))
//             continue;   // w now restarts at the exit of the empty cube around the block
//         if (!<cell live bit>) continue;   // no level can cross it: no corner is read
//         ... the cell as before ...
//     }
// A live bit is the same test per cell (its corners' δ range), so it too only drops cells that
// cannot hold a hit.
// dn: the direction the walk was started with (dda_init(og, dn, n, ·)).
// Exactness: the exit t_exit (surf_block_exit) of the cube of empty blocks is the far-plane
// crossing (k − o)·(1/d) with dda.glsl's own formula, hence bit-identical to the t at which the
// continuous walk leaves it; the restart (surf_dda_restart, = dda_init(og, dn, n, t_exit))
// settles the cell with those same crossings and recomputes t_next with the same formula, so the
// pieces (cell, t0, t1) after the cube are exactly the ones the continuous walk would produce
// (tested piece by piece in src/math/surface_blocks.rs). Should rounding ever settle the restart
// back inside the skipped block, `skipped` makes the walk go through it cell by cell; back inside
// the cube but in another block, that block skips on from a later t (the exit lies at or past the
// current piece's end, same formula, rounding monotone): never a loop.
// The masks must describe the current δ: rebuild them after every δ update (or use a margin that
// bounds the drift since they were built).
#ifndef SURFACE_BLOCKS_GLSL
#define SURFACE_BLOCKS_GLSL

#include "dda.glsl"

// SURF_NO_BLOCK ("no block skipped yet"), SURF_MASK_BITS, SURF_RADIUS_SHIFT, SURF_MAX_RADIUS,
// SURF_BLOCK_BIG and SURF_BOX_WORDS: src/abi/consts.rs (abi.glsl).

// Blocks per axis of an n³-vertex grid (n ≥ 2) with 2^shift-cell blocks: ceil((n − 1)/2^shift).
uint surf_blocks_per_axis(uint n, uint shift) {
    return (n + (1u << shift) - 2u) >> shift;
}

// Words of live-cell bits of an n³-vertex grid: ⌈n³/32⌉ (at least 1). The walks' skip structure
// is these words (bit i of word i/32: the cell with lower-corner slot i is live — all 8 corners
// allocated and some level within [cmin − margin, cmax + margin]; kernel surface_live_cells),
// then the nb³ block masks.
uint surf_live_words(uint n) {
    return max((n * n * n + 31u) >> 5u, 1u);
}

// Whether the cell with lower-corner slot ci is live in the skip structure `words`.
#define SURF_CELL_LIVE(SKIP, CI) ((SKIP.v[(CI) >> 5u] & (1u << ((CI) & 31u))) != 0u)

// Low bits of a block word: the level mask (≤ 8 levels); bits from SURF_RADIUS_SHIFT on: the
// empty radius of a mask-0 block (0 ≤ r ≤ SURF_MAX_RADIUS; 0 for a block with levels).

// Linear index of the block holding cell l.
uint surf_block_index(ivec3 l, uint nb, uint shift) {
    uvec3 b = uvec3(l >> int(shift));
    return (b.x * nb + b.y) * nb + b.z;
}

// Vertex box [lo, hi] of the blocks within Chebyshev distance r of the block holding cell l (the
// block itself for r = 0), clipped to the grid of n³ vertices.
void surf_block_box(ivec3 l, int n, uint shift, uint r, out vec3 lo, out vec3 hi) {
    ivec3 b = l >> int(shift);
    int ri = int(r);
    lo = vec3(max(b - ri, ivec3(0)) << int(shift));
    hi = vec3(min((b + ri + 1) << int(shift), ivec3(n - 1)));
}

// Start of a block's δ range scan (the largest float): bmin = SURF_BLOCK_BIG and
// bmax = −SURF_BLOCK_BIG, an empty range (bmin > bmax) that stays so without allocated vertices.

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

// t at which walk w leaves the box of the blocks within r of the block holding cell l
// (surf_block_box): min over moving axes of the box's far-plane crossing (k − o)·(1/d) (o, 1/d as
// stored in w) — bit-identical to ray_box(og, dn, box, ·).y, since for 1/d > 0 the far crossing
// is the larger of the two (rounding is monotone), and a still axis lies inside the box (no
// constraint).
float surf_block_exit(Dda w, ivec3 l, int n, uint shift, uint r) {
    vec3 lo, hi;
    surf_block_box(l, n, shift, r, lo, hi);
    float t = DDA_BIG;
    for (int a = 0; a < 3; a++) {
        if (w.step[a] == 0) continue;
        precise float tf = ((w.step[a] > 0 ? hi[a] : lo[a]) - w.o[a]) * w.inv[a];
        t = min(t, tf);
    }
    return t;
}

// Restarts walk w (started as dda_init(og, dn, n, ·)) at t ≥ its current entry t: the state
// dda_init(og, dn, n, t) returns (same cell estimate and settling, same t_next formula), without
// redoing the grid clip (w keeps o, 1/d, step and t_end; t lies past the grid entry).
void surf_dda_restart(inout Dda w, vec3 dn, int n, float t) {
    vec3 d = dda_flush(dn);
    ivec3 up = max(w.step, ivec3(0));
    precise vec3 p = w.o + t * d;
    ivec3 c = ivec3(floor(clamp(p, vec3(-1.0), vec3(float(n)))));
    precise vec3 tn = (vec3(c + up) - w.o) * w.inv;
    c += ivec3(lessThanEqual(tn, vec3(t))) * w.step;
    precise vec3 tp = (vec3(c + 1 - up) - w.o) * w.inv;
    c -= ivec3(greaterThan(tp, vec3(t))) * w.step;
    w.cell = clamp(c, ivec3(0), ivec3(n - 2));
    precise vec3 tx = (vec3(w.cell + up) - w.o) * w.inv;
    w.t_next = mix(tx, vec3(DDA_BIG), equal(d, vec3(0.0)));
    w.t = t;
    if (!(t < w.t_end)) {  // past the grid: the walk ends at the next dda_next
        w.t_next = vec3(DDA_BIG);
        w.t = -DDA_BIG;
        w.t_end = -DDA_BIG;
    }
}

// Words after the block masks in a skip structure: the box of the allocated vertices, lo x, y, z
// then hi x, y, z (vertex coordinates; lo > hi when nothing is allocated; written once per grid,
// Rust math::surface_blocks::alloc_box). A cell the walk can solve has its 8 corners allocated, so
// it lies inside: a walk runs from dda_init(og, dn, n, t_in) and ends at the first piece entered
// at t_out or later. Exact: t_in is a plane crossing computed with the DDA's own formula
// (ray_box), and dda_init at such a t is the continuous walk's state there (as for a block exit).
// SURF_BOX_WORDS words.

// The span (t_in, t_out) of the ray inside the allocated box [lo, hi]; t_in ≥ t_out (or NaN) when
// it misses it.
vec2 surf_box_span(vec3 og, vec3 dn, uvec3 lo, uvec3 hi) {
    if (any(greaterThan(lo, hi))) return vec2(DDA_BIG, -DDA_BIG);
    return ray_box(og, dn, vec3(lo), vec3(hi), 0.0);
}

// Called when the walk w (started as dda_init(og, dn, n, ·)) has just produced the piece of cell l
// whose block bi has mask 0 and empty radius r: unless bi is the block skipped last, restarts w at
// the exit of the cube of blocks within r of it, records bi in `skipped` and returns true (the
// caller drops the cell and continues with dda_next); returns false (walk the cell as usual) when
// bi == skipped.
bool surf_block_skip(inout Dda w, vec3 dn, int n, ivec3 l, uint bi, inout uint skipped, uint shift,
                     uint r) {
    if (bi == skipped) return false;
    surf_dda_restart(w, dn, n, surf_block_exit(w, l, n, shift, r));
    skipped = bi;
    return true;
}

#endif
