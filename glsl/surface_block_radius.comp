#version 460
// surface_block_radius — the empty radius of every mask-0 block of the stage-2 skip structure
// (glsl/lib/surface_blocks.glsl): the Chebyshev distance d, in blocks, to the nearest block with
// levels, capped at SURF_MAX_RADIUS + 1, found in three separable passes (min and max compose
// separably for that distance); r = d − 1 is or-ed into the block's word from SURF_RADIUS_SHIFT on.
// Pass p (0, 1, 2: along x, y, z): value(b) = min over |k| ≤ SURF_MAX_RADIUS with b + k·e_p inside
// the grid of max(|k|, src(b + k·e_p)), src = 0 for a block with levels and SURF_MAX_RADIUS + 1
// for one without (pass 0, read from the masks), else the previous pass's values. Pass 0 writes
// scratch[0, nb³), pass 1 scratch[nb³, 2nb³), pass 2 the radii into the block words.
// Thread mapping: one invocation per block, flat index (bx·nb + by)·nb + bz.
// Inputs: blocks (the nb³ level masks of surface_blocks), scratch (2·nb³ u32), nb, pass.
// Output: scratch (passes 0, 1), blocks (pass 2: masks unchanged, radii or-ed in).
// CPU twin: `cpu::surface_block_radius`.
#include "common.glsl"
#include "surface_blocks.glsl"
layout(local_size_x = 64) in;

layout(push_constant, scalar) uniform Push {
    U32Buf blocks;
    U32Buf scratch;
    uint nb;
    uint pass;
} pc;

// The pass's source value of block i.
uint source(uint i) {
    uint count = pc.nb * pc.nb * pc.nb;
    if (pc.pass == 0u) return (pc.blocks.v[i] & SURF_MASK_BITS) != 0u ? 0u : SURF_MAX_RADIUS + 1u;
    return pc.scratch.v[(pc.pass - 1u) * count + i];
}

void main() {
    uint b = flat_id();
    uint nb = pc.nb;
    uint count = nb * nb * nb;
    if (b >= count) return;
    uint stride = pc.pass == 0u ? nb * nb : (pc.pass == 1u ? nb : 1u);
    uint pos = (b / stride) % nb;
    uint best = SURF_MAX_RADIUS + 1u;
    // max(k, ·) ≥ k: nothing at k ≥ best can lower it.
    for (uint k = 0u; k <= SURF_MAX_RADIUS && k < best; k++) {
        if (pos >= k) best = min(best, max(k, source(b - k * stride)));
        if (pos + k < nb) best = min(best, max(k, source(b + k * stride)));
    }
    if (pc.pass < 2u) {
        pc.scratch.v[pc.pass * count + b] = best;
        return;
    }
    uint word = pc.blocks.v[b];
    if ((word & SURF_MASK_BITS) == 0u) pc.blocks.v[b] = word | ((best - 1u) << SURF_RADIUS_SHIFT);
}
