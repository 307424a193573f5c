#version 460
// surface_blocks — per 2^block_shift-cell block of the stage-2 grid, the levels it can contain (coarse
// empty-space skipping for the surface walk; glsl/lib/surface_blocks.glsl has the conventions).
// Thread mapping: one invocation per block, flat index (bx·nb + by)·nb + bz, nb = ceil((n−1)/B),
// B = 2^block_shift.
// (A workgroup per block with a shared-memory reduction ran slower on lavapipe: its barriers;
// docs/tuning.md.)
// Inputs: links (n³ i32, < 0 unallocated), delta (per allocated vertex), levels[n_levels ≤ 8],
// margin ≥ 0, block_shift. Output: blocks[b] = bit i set iff τ_i ∈ [bmin − margin, bmax + margin],
// bmin/bmax over the allocated vertices of the block's vertex range [Bb, min(Bb+B, n−1)]³ (0 if
// none); the empty radii are added by surface_block_radius.
// min/max are exact, so the scan order does not matter (signed zeros aside, which compare alike).
// CPU twin: `cpu::surface_blocks::build_blocks`.
#include "common.glsl"
#include "surface_blocks.glsl"
layout(local_size_x = 64) in;

layout(push_constant, scalar) uniform Push {
    I32Buf links;
    F32Buf delta;
    F32Buf levels;
    U32Buf blocks;
    uint n;
    uint n_levels;
    float margin;
    uint block_shift;
} pc;

void main() {
    uint b = flat_id();
    uint n = pc.n;
    uint shift = pc.block_shift;
    uint nb = surf_blocks_per_axis(n, shift);
    if (b >= nb * nb * nb) return;
    ivec3 l = ivec3(int(b / (nb * nb)), int((b / nb) % nb), int(b % nb)) << int(shift);
    vec3 lo, hi;
    surf_block_box(l, int(n), shift, 0u, lo, hi);
    ivec3 v0 = ivec3(lo);
    ivec3 v1 = ivec3(hi);
    float bmin = SURF_BLOCK_BIG;
    float bmax = -SURF_BLOCK_BIG;
    for (int x = v0.x; x <= v1.x; x++) {
        for (int y = v0.y; y <= v1.y; y++) {
            uint row = (uint(x) * n + uint(y)) * n;
            for (int z = v0.z; z <= v1.z; z++) {
                int k = pc.links.v[row + uint(z)];
                if (k < 0) continue;
                float d = pc.delta.v[k];
                bmin = min(bmin, d);
                bmax = max(bmax, d);
            }
        }
    }
    uint nl = min(pc.n_levels, 8u);
    float lv[8];
    for (uint i = 0u; i < 8u; i++) lv[i] = i < nl ? pc.levels.v[i] : 0.0;
    pc.blocks.v[b] = surf_block_mask(bmin, bmax, pc.margin, lv, nl);
}
