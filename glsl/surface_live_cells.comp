#version 460
// surface_live_cells — the live-cell bits of the stage-2 walks' skip structure
// (glsl/lib/surface_blocks.glsl): bit i of word i/32 is set iff the cell with lower-corner slot i
// has its 8 corners allocated and some level τ lies within [cmin − margin, cmax + margin] of their
// δ (surf_block_mask of the cell's range ≠ 0). A cell without the bit holds no hit while δ has
// drifted by ≤ margin since (min/max are exact, so the scan order does not matter).
// Thread mapping: one invocation per bit word w (cells 32w … 32w + 31, x-major slots).
// Inputs: complete (the static complete-cell bits, same layout: a word without any is skipped
// unread), links (n³ i32), delta (per allocated vertex), levels[n_levels ≤ 8], n, margin ≥ 0.
// Output: live[w]. CPU twin: `cpu::surface_live_cells::surface_live_cells`.
#include "common.glsl"
#include "surface_blocks.glsl"
layout(local_size_x = 64) in;

layout(push_constant, scalar) uniform Push {
    U32Buf complete;
    I32Buf links;
    F32Buf delta;
    F32Buf levels;
    U32Buf live;
    uint n;
    uint n_levels;
    float margin;
} pc;

void main() {
    uint w = flat_id();
    uint n = pc.n;
    if (w >= surf_live_words(n)) return;
    uint bits = pc.complete.v[w];
    uint live = 0u;
    if (bits != 0u) {
        uint nl = min(pc.n_levels, 8u);
        float lv[8];
        for (uint i = 0u; i < 8u; i++) lv[i] = i < nl ? pc.levels.v[i] : 0.0;
        uint nz = n;
        uint nyz = n * n;
        while (bits != 0u) {
            int b = findLSB(bits);
            bits &= bits - 1u;
            uint s = 32u * w + uint(b);
            float cmin = SURF_BLOCK_BIG;
            float cmax = -SURF_BLOCK_BIG;
            for (uint k = 0u; k < 8u; k++) {
                uint cs = s + ((k >> 2u) & 1u) * nyz + ((k >> 1u) & 1u) * nz + (k & 1u);
                float d = pc.delta.v[uint(pc.links.v[cs])];
                cmin = min(cmin, d);
                cmax = max(cmax, d);
            }
            if (surf_block_mask(cmin, cmax, pc.margin, lv, nl) != 0u) live |= 1u << uint(b);
        }
    }
    pc.live.v[w] = live;
}
