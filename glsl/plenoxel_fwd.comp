#version 460
// plenoxel_fwd — stage-1 volume rendering of a batch of rays (method.md §2).
// Thread mapping: one invocation per ray.
// Inputs: the grid (links, density, sh, occupancy), rays as 6 floats (scene origin, unit
// direction), grid = p·scale + offset, stop threshold on transmittance, bg (Background: what is
// composited behind: C = Σ w_i c_i + T·B, B its colour behind its spheres, background.glsl).
// Outputs: rgb (3 floats per ray); step-buffer counters += samples shaded,
// samples evaluated at σ ≤ 1e-8, samples skipped by the occupancy volume (subgroup-reduced).
// CPU twin: `cpu::plenoxel_fwd::render`.
#include "common.glsl"
#include "background.glsl"
layout(local_size_x = 64) in;

layout(push_constant, scalar) uniform Push {
    I32Buf links;
    F32Buf density;
    F32Buf sh;
    U32Buf occ;
    F32Buf rays;
    F32Buf rgb;
    StepRecord step;
    BackgroundBuf bg;
    uvec3 res;
    vec3 scale;
    vec3 offset;
    uint n_rays;
    float stop_thresh;
} pc;

#include "plenoxel.glsl"
#include "step.glsl"

void main() {
    uint r = flat_id();
    if (r >= pc.n_rays) return;
    vec3 ro = vec3(pc.rays.v[6u * r], pc.rays.v[6u * r + 1u], pc.rays.v[6u * r + 2u]);
    vec3 rd = vec3(pc.rays.v[6u * r + 3u], pc.rays.v[6u * r + 4u], pc.rays.v[6u * r + 5u]);
    vec3 color = vec3(0.0);
    float T = 1.0;
    PlenoxelCounts counts = PLENOXEL_COUNTS_ZERO;
    March m;
    if (march_init(ro, rd, pc.scale, pc.offset, pc.res, m)) {
        float y[9];
        sh_basis(rd, y);
        uint k = 0u;
        Sample s;
        while (march_next(m, k, counts, s)) {
            counts.shaded++;
            float alpha = sample_alpha(s.sigma, m.delta);
            vec3 c = max(sample_color_raw(s.lk, s.w, y), vec3(0.0));
            precise float wt = T * alpha;
            precise vec3 acc = color + wt * c;
            color = acc;
            precise float tn = T * (1.0 - alpha);
            T = tn;
            if (T < pc.stop_thresh) break;
        }
    }
    float t_bg;
    precise vec3 outc = color + T * background_behind(pc.bg.v[0], ro, rd, t_bg);
    pc.rgb.v[3u * r] = outc.x;
    pc.rgb.v[3u * r + 1u] = outc.y;
    pc.rgb.v[3u * r + 2u] = outc.z;
    add_stats(counts);
}
