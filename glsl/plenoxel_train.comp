#version 460
// plenoxel_train — one stage-1 training pass over a batch of rays: forward march, fused MSE
// gradient dL/dC = grad_scale·(C − target) (grad_scale = 2/(3B)), then a second march that
// scatters dL/dσ (with svox2's Cauchy sparsity term λ·4σ/(1 + 2σ²) per sample when
// params.sparsity = λ > 0) and dL/dSH to the 8 corners of each sample's cell (method.md §2; svox2's
// backward). Consecutive samples in the same cell are summed in registers and flushed with one
// float atomic per corner and parameter when the cell changes (SH needs only 3 accumulators per
// corner: the basis Y_k is constant along a ray).
// Thread mapping: one invocation per ray.
// Inputs: grid, occupancy, rays (6 floats), targets (3 floats), params (PlenoxelParams: scale,
// offset, stop threshold, grad_scale), res, bg (Background: C = Σ w_i c_i + T·B, B the colour
// behind the spheres in front of it, background.glsl).
// Outputs: grad_density, grad_sh (+= by float atomics; each vertex that gets one is touched), ray_loss[r] = Σ_channels (C − target)²,
// when bg.learn ≠ 0, bg.grad += Σ_rays dL/dC·T·T_L (subgroup-reduced float atomics), learned
// spheres' gradient += (background_msi.glsl),
// sample counters as in plenoxel_fwd, touched vertices listed in the step buffer. CPU twin: `cpu::plenoxel_train::train`.
#extension GL_EXT_shader_atomic_float : require
#define BG_MSI_BACKWARD
#include "common.glsl"
#include "background.glsl"
layout(local_size_x = 64) in;


layout(push_constant, scalar) uniform Push {
    I32Buf links;
    F32Buf density;
    F32Buf sh;
    U32Buf occ;
    F32Buf rays;
    F32Buf targets;
    F32Buf grad_density;
    F32Buf grad_sh;
    F32Buf ray_loss;
    StepRecord step;
    PlenoxelParamsBuf params;
    BackgroundBuf bg;
    uvec3 res;
    uint n_rays;
} pc;

#include "plenoxel.glsl"
#include "step.glsl"

// Adds the per-cell accumulators to the gradients (one atomic per corner and parameter) and
// clears them.
uint flush(float y[9], int cur_lk[8], inout float acc_sigma[8], inout vec3 acc_color[8]) {
    uint adds = 0u;
    for (int i = 0; i < 8; i++) {
        int l = cur_lk[i];
        float gs = acc_sigma[i];
        vec3 gc = acc_color[i];
        acc_sigma[i] = 0.0;
        acc_color[i] = vec3(0.0);
        if (l < 0 || (gs == 0.0 && gc == vec3(0.0))) continue;
        touch(uint(l));
        if (gs != 0.0) {
            atomicAdd(pc.grad_density.v[l], gs);
            adds++;
        }
        for (int ch = 0; ch < 3; ch++) {
            if (gc[ch] == 0.0) continue;
            uint row = uint(l) * 27u + uint(ch) * 9u;
            for (int k = 0; k < 9; k++) atomicAdd(pc.grad_sh.v[row + uint(k)], gc[ch] * y[k]);
            adds += 9u;
        }
    }
    return adds;
}

void main() {
    uint r = flat_id();
    if (r >= pc.n_rays) return;
    vec3 ro = vec3(pc.rays.v[6u * r], pc.rays.v[6u * r + 1u], pc.rays.v[6u * r + 2u]);
    vec3 rd = vec3(pc.rays.v[6u * r + 3u], pc.rays.v[6u * r + 4u], pc.rays.v[6u * r + 5u]);
    vec3 target = vec3(pc.targets.v[3u * r], pc.targets.v[3u * r + 1u], pc.targets.v[3u * r + 2u]);
    PlenoxelParams prm = pc.params.v[0];
    float stop_thresh = prm.stop_thresh;
    float y[9];
    sh_basis(rd, y);
    March m;
    bool hit = march_init(ro, rd, prm.scale, prm.offset, pc.res, m);
    PlenoxelCounts counts = PLENOXEL_COUNTS_ZERO;

    // Forward: C and the final transmittance.
    vec3 color = vec3(0.0);
    float T = 1.0;
    uint k = 0u;
    Sample s;
    uint replay[REPLAY];
    uint shaded = 0u;
    while (hit && march_next(m, k, counts, s)) {
        if (shaded < REPLAY) replay[shaded] = k - 1u;
        shaded++;
        counts.shaded++;
        float alpha = sample_alpha(s.sigma, m.delta);
        vec3 c = max(sample_color_raw(s.lk, s.w, y), vec3(0.0));
        precise float wt = T * alpha;
        precise vec3 acc = color + wt * c;
        color = acc;
        precise float tn = T * (1.0 - alpha);
        T = tn;
        if (T < stop_thresh) break;
    }
    Background bgr = pc.bg.v[0];
    float t_bg;
    vec3 behind = background_behind(bgr, ro, rd, t_bg);
    precise vec3 total = color + T * behind;
    precise vec3 diff = total - target;
    pc.ray_loss.v[r] = dot(diff, diff);
    vec3 g_c = prm.grad_scale * diff;
    // dL/dB = g·T_final, dL/dbg = g·T_final·T_L (T before the backward pass reuses it).
    precise vec3 g_behind = g_c * T;
    precise vec3 g_bg = g_behind * t_bg;
    background_spheres_grad(bgr, ro, rd, behind, g_behind);

    // Backward: the same samples again, in the same order.
    // Per-cell gradient accumulators, flushed when the sample's cell changes.
    int cur_lk[8];
    float acc_sigma[8];
    vec3 acc_color[8];
    for (int i = 0; i < 8; i++) {
        cur_lk[i] = -1;
        acc_sigma[i] = 0.0;
        acc_color[i] = vec3(0.0);
    }
    ivec3 cur_cell = ivec3(-1);
    vec3 accum = vec3(0.0);
    T = 1.0;
    k = 0u;
    PlenoxelCounts replayed = PLENOXEL_COUNTS_ZERO; // the forward pass already counted these samples
    for (uint j = 0u; hit; j++) {
        if (shaded <= REPLAY) {
            if (j == shaded) break;
            sample_at(m, replay[j], s);
        } else if (!march_next(m, k, replayed, s)) {
            break;
        }
        float alpha = sample_alpha(s.sigma, m.delta);
        vec3 raw = sample_color_raw(s.lk, s.w, y);
        vec3 c = max(raw, vec3(0.0));
        precise float wt = T * alpha;
        precise vec3 acc = accum + wt * c;
        accum = acc;
        precise float tn = T * (1.0 - alpha);
        // dL/dσ = Δ·g·(T_next·c − (C − C_≤i)); dL/dc = g·w, zero where the ReLU clamps.
        precise vec3 rest = total - accum;
        precise vec3 dsig3 = g_c * (tn * c - rest);
        precise float d_sigma = m.delta * (dsig3.x + dsig3.y + dsig3.z);
        if (prm.sparsity > 0.0) {
            precise float den = 1.0 + 2.0 * (s.sigma * s.sigma);
            precise float ds = prm.sparsity * (4.0 * s.sigma / den);
            d_sigma += ds;
        }
        vec3 d_color = mix(vec3(0.0), g_c * wt, greaterThan(raw, vec3(0.0)));
        if (s.l != cur_cell) {
            counts.atomic_adds += flush(y, cur_lk, acc_sigma, acc_color);
            cur_cell = s.l;
            cur_lk = s.lk;
        }
        for (int i = 0; i < 8; i++) {
            precise float as = acc_sigma[i] + s.w[i] * d_sigma;
            acc_sigma[i] = as;
            precise vec3 ac = acc_color[i] + s.w[i] * d_color;
            acc_color[i] = ac;
        }
        T = tn;
        if (T < stop_thresh) break;
    }
    counts.atomic_adds += flush(y, cur_lk, acc_sigma, acc_color);
    if (pc.bg.v[0].learn != 0u) BACKGROUND_GRAD_ADD(pc.bg, g_bg);
    add_stats(counts);
}
