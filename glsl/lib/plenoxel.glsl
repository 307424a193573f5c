// plenoxel.glsl — the stage-1 ray march shared by plenoxel_fwd, plenoxel_train and plenoxel_weights
// (method.md §2): ray → grid units, slab clip to [−0.5, N − 0.5]³, samples every 0.5 voxel at
// t_k = t0 + 0.5·k, each clamped to [0, N − 1] with cell = min(floor, N − 2); σ and SH are
// trilinear (unallocated corners = 0); a sample with σ ≤ 1e-8 is skipped (ReLU).
// Empty-space skipping: an occupancy volume with one u32 per block of 2^OCC_SHIFT cells per axis
// (written by occupancy.comp); a sample in an empty block jumps to the first lattice sample past the
// block, which skips only samples whose σ is ≤ 1e-8 anyway, so results are unchanged.
// Rust twin: src/math/plenoxel.rs (same arithmetic; `precise` stops contraction into FMAs).
// Kernels that need only the constants and occ_dims define PLENOXEL_CONSTANTS_ONLY first.
// Include AFTER the kernel's push-constant block `pc`, which must have the members links (I32Buf),
// density, sh (F32Buf), occ (U32Buf) and res (uvec3). (Buffer references are read from `pc`
// directly: a struct holding them in a local variable makes glslang emit invalid SPIR-V — a
// Function-storage pointer without AliasedPointer/RestrictPointer.)
#ifndef PLENOXEL_GLSL
#define PLENOXEL_GLSL

#include "trilerp.glsl"
#include "sh.glsl"
#include "dda.glsl"

// SIGMA_EPS, STEP, SKIP_MARGIN (skips stop this far before the block exit, so rounding never
// skips a live sample), OCC_SHIFT (occupancy blocks are 2^OCC_SHIFT cells per axis):
// src/abi/consts.rs (abi.glsl).

struct March {
    vec3 o;      // origin, grid units
    vec3 d;      // unit direction, grid units
    float t0;    // first sample
    float t_end; // box exit
    float delta; // world length of one 0.5-voxel step
};

// Sets up the march of the scene-space ray (ro, rd) with grid = p·scale + offset. False: no hit.
bool march_init(vec3 ro, vec3 rd, vec3 scale, vec3 offset, uvec3 res, out March m) {
    precise vec3 og = ro * scale + offset;
    precise vec3 dg = rd * scale;
    precise float len = sqrt(dg.x * dg.x + dg.y * dg.y + dg.z * dg.z);
    precise vec3 dn = dg / len;
    m.o = og;
    m.d = dn;
    m.delta = STEP / len;
    vec2 box = ray_box(og, dn, vec3(-0.5), vec3(res) - vec3(0.5), 0.0);
    m.t0 = box.x;
    m.t_end = box.y;
    return box.x < box.y;
}

float march_t(March m, uint k) {
    precise float t = m.t0 + STEP * float(k);
    return t;
}

// Cell and local position of the sample at t.
void march_cell(March m, float t, uvec3 res, out ivec3 l, out vec3 p) {
    precise vec3 pos = m.o + m.d * t;
    pos = clamp(pos, vec3(0.0), vec3(res - uvec3(1)));
    l = min(ivec3(floor(pos)), ivec3(res) - ivec3(2));
    precise vec3 q = pos - vec3(l);
    p = q;
}

// Blocks per axis of the occupancy volume.
uvec3 occ_dims(uvec3 res) {
    uint b = 1u << OCC_SHIFT;
    return (res - uvec3(1) + uvec3(b - 1u)) >> OCC_SHIFT;
}

#ifndef PLENOXEL_CONSTANTS_ONLY
// If the sample in cell l lies in an empty block, the index of the first sample to look at next
// (> k); otherwise k.
uint march_skip(March m, uint k, ivec3 l) {
    uvec3 b = uvec3(l) >> OCC_SHIFT;
    uvec3 nb = occ_dims(pc.res);
    if (pc.occ.v[(b.x * nb.y + b.y) * nb.z + b.z] != 0u) return k;
    float bs = float(1u << OCC_SHIFT);
    vec3 lo = vec3(b) * bs;
    vec3 hi = min(lo + vec3(bs), vec3(pc.res - uvec3(1)));
    float t_exit = 3.402823466e38;
    for (int a = 0; a < 3; a++) {
        if (m.d[a] != 0.0) {
            precise float ta = ((m.d[a] > 0.0 ? hi[a] : lo[a]) - m.o[a]) / m.d[a];
            t_exit = min(t_exit, ta);
        }
    }
    precise float steps = (t_exit - SKIP_MARGIN - m.t0) / STEP;
    float next = ceil(steps);
    if (!(next < 4.0e9)) return 0xffffffffu;
    return max(k + 1u, uint(max(next, 0.0)));
}

// σ at trilinear weights w (unallocated corners count 0).
float sample_sigma(int lk[8], float w[8]) {
    precise float s = 0.0;
    for (int i = 0; i < 8; i++) {
        if (lk[i] >= 0) s += w[i] * pc.density.v[lk[i]];
    }
    return s;
}

// Pre-ReLU colour Σ_k Y_k·sh_k + 0.5 per channel, SH trilerped with weights w.
vec3 sample_color_raw(int lk[8], float w[8], float y[9]) {
    float c[27];
    for (int k = 0; k < 27; k++) c[k] = 0.0;
    for (int i = 0; i < 8; i++) {
        if (lk[i] < 0) continue;
        uint row = uint(lk[i]) * 27u;
        for (int k = 0; k < 27; k++) {
            precise float acc = c[k] + w[i] * pc.sh.v[row + uint(k)];
            c[k] = acc;
        }
    }
    vec3 raw;
    for (int ch = 0; ch < 3; ch++) {
        precise float acc = 0.5;
        for (int k = 0; k < 9; k++) {
            precise float a2 = acc + y[k] * c[ch * 9 + k];
            acc = a2;
        }
        raw[ch] = acc;
    }
    return raw;
}

// α = 1 − exp(−σΔ).
float sample_alpha(float sigma, float delta) {
    precise float a = 1.0 - exp(-sigma * delta);
    return a;
}

// One shaded sample: its cell, corner links, trilinear weights and σ.
struct Sample {
    ivec3 l;
    int lk[8];
    float w[8];
    float sigma;
};

// Corner links, trilinear weights and σ of a sample in cell l at local position p.
void sample_fill(vec3 p, inout Sample s) {
    cell_links(pc.links, pc.res, s.l, s.lk);
    trilerp_weights(p, s.w);
    s.sigma = sample_sigma(s.lk, s.w);
}

// The sample of index k (a replay of one that march_next returned).
void sample_at(March m, uint k, out Sample s) {
    vec3 p;
    march_cell(m, march_t(m, k), pc.res, s.l, p);
    sample_fill(p, s);
}

// Advances the march from sample index k to the next sample with σ > SIGMA_EPS and returns true,
// or returns false at the box exit. counts.empty += samples evaluated with σ ≤ SIGMA_EPS,
// counts.skipped += samples jumped over by the occupancy volume.
bool march_next(March m, inout uint k, inout PlenoxelCounts counts, out Sample s) {
    while (true) {
        float t = march_t(m, k);
        if (!(t < m.t_end)) return false;
        vec3 p;
        march_cell(m, t, pc.res, s.l, p);
        uint next = march_skip(m, k, s.l);
        if (next != k) {
            if (!(march_t(m, next) < m.t_end)) {
                counts.skipped += uint(ceil((m.t_end - t) / STEP));
                return false;
            }
            counts.skipped += next - k;
            k = next;
            continue;
        }
        k++;
        sample_fill(p, s);
        if (s.sigma > SIGMA_EPS) return true;
        counts.empty++;
    }
    return false;
}

#endif


#endif
