#version 460
// plenoxel_weights — the pruning weights of stage 1: for every shaded sample of every ray, each
// allocated corner's max_weight = max(max_weight, w_sample·w_trilinear), with w_sample = T·α.
// The march stops once T < stop_thresh (svox2 uses 0.2 for this pass).
// Thread mapping: one invocation per ray. Inputs: grid, occupancy, rays (6 floats), scale/offset.
// Output: max_weight per allocated vertex, as float bits under uint atomicMax (weights are ≥ 0, so
// the bit patterns order like the floats; no float-atomic feature needed).
// CPU twin: `cpu::plenoxel_weights::max_weights`.
#include "common.glsl"
layout(local_size_x = 64) in;

layout(push_constant, scalar) uniform Push {
    I32Buf links;
    F32Buf density;
    F32Buf sh;
    U32Buf occ;
    F32Buf rays;
    U32Buf max_weight;
    uvec3 res;
    vec3 scale;
    vec3 offset;
    uint n_rays;
    float stop_thresh;
} pc;

#include "plenoxel.glsl"

void main() {
    uint r = flat_id();
    if (r >= pc.n_rays) return;
    vec3 ro = vec3(pc.rays.v[6u * r], pc.rays.v[6u * r + 1u], pc.rays.v[6u * r + 2u]);
    vec3 rd = vec3(pc.rays.v[6u * r + 3u], pc.rays.v[6u * r + 4u], pc.rays.v[6u * r + 5u]);
    March m;
    if (!march_init(ro, rd, pc.scale, pc.offset, pc.res, m)) return;
    float T = 1.0;
    uint k = 0u;
    PlenoxelCounts counts = PLENOXEL_COUNTS_ZERO;
    Sample s;
    while (march_next(m, k, counts, s)) {
        float alpha = sample_alpha(s.sigma, m.delta);
        precise float wt = T * alpha;
        for (int i = 0; i < 8; i++) {
            if (s.lk[i] < 0) continue;
            precise float wv = wt * s.w[i];
            atomicMax(pc.max_weight.v[s.lk[i]], floatBitsToUint(wv));
        }
        precise float tn = T * (1.0 - alpha);
        T = tn;
        if (T < pc.stop_thresh) break;
    }
}
