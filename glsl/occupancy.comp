#version 460
// occupancy — the empty-space skipping volume of the stage-1 march.
// Thread mapping: one invocation per block of 8³ cells (flat index over occ_dims(res)).
// Inputs: links, density, res. Output: occ[block] = 1 when any vertex of the block's cells
// (vertex range [8b, min(8b + 8, N − 1)] per axis) is allocated with σ > SIGMA_EPS/2, else 0.
// CPU twin: `cpu::occupancy::occupancy`.
#include "common.glsl"
layout(local_size_x = 64) in;

layout(push_constant, scalar) uniform Push {
    I32Buf links;
    F32Buf density;
    U32Buf occ;
    uvec3 res;
} pc;

#define PLENOXEL_CONSTANTS_ONLY
#include "plenoxel.glsl"

void main() {
    uvec3 nb = occ_dims(pc.res);
    uint id = flat_id();
    if (id >= nb.x * nb.y * nb.z) return;
    uvec3 b = uvec3(id / (nb.y * nb.z), (id / nb.z) % nb.y, id % nb.z);
    uvec3 lo = b << OCC_SHIFT;
    uvec3 hi = min(lo + uvec3(1u << OCC_SHIFT), pc.res - uvec3(1));
    uint occupied = 0u;
    for (uint x = lo.x; x <= hi.x && occupied == 0u; x++) {
        for (uint y = lo.y; y <= hi.y && occupied == 0u; y++) {
            uint base = (x * pc.res.y + y) * pc.res.z;
            for (uint z = lo.z; z <= hi.z; z++) {
                int l = pc.links.v[base + z];
                if (l >= 0 && pc.density.v[l] > 0.5 * SIGMA_EPS) {
                    occupied = 1u;
                    break;
                }
            }
        }
    }
    pc.occ.v[id] = occupied;
}
