#version 460
// sample_rays — draws a batch of training rays on the device (CPU twin: cpu::sample_rays).
// Thread mapping: one workgroup per run of SAMPLE_SORT_RAYS rays (the last run may be shorter);
// its 256 invocations each draw, sort and write every 256th ray of the run.
// Ray i of the batch picks pixel splitmix64(seed + (i + 1)·γ) mod n_pixels over all pixels of
// the split (uniform with replacement, a counter-based draw: no state between batches), as the
// key (view << 2·key_bits) | morton(x, y), which determines the pixel. Each run's keys are sorted
// in shared memory (bitonic, padded with all-ones keys to a power of two), so within a run the
// rays are ordered by view and Z-order (neighbouring invocations of the training kernels trace
// nearby rays). Then each ray is written: origin = the view's camera centre in the scaled world,
// unit direction = normalize(R·((x + ½ − cx)/fx, −(y + ½ − cy)/fy, −1)) as data::Camera::pixel_ray,
// target = the pixel's composited RGB / 255.
// Inputs: pixels (RGBA8 packed in a u32 per pixel, views × height × width, row-major), cams
// (SampleCamera per view). Outputs: rays (6 floats), targets (3 floats), keys (sorted u64).
#include "common.glsl"
layout(local_size_x = 256) in;

layout(buffer_reference, scalar, buffer_reference_align = 8) buffer KeyBuf { uint64_t v[]; };

layout(push_constant, scalar) uniform Push {
    U32Buf pixels;
    SampleCameraBuf cams;
    F32Buf rays;
    F32Buf targets;
    KeyBuf keys;
    uint64_t seed;
    uint64_t n_pixels;
    uint width;
    uint height;
    uint n_rays;
    // Bits of a pixel coordinate: max(width, height) − 1 < 2^key_bits ≤ 2^16.
    uint key_bits;
} pc;

shared uint64_t s_keys[SAMPLE_SORT_RAYS];

// SplitMix64's output function (Steele, Lea & Flood 2014) on the counter seed + (i + 1)·γ.
uint64_t splitmix64(uint64_t seed, uint i) {
    uint64_t z = seed + uint64_t(i + 1u) * 0x9e3779b97f4a7c15ul;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ul;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebul;
    return z ^ (z >> 31);
}

// The bits of v (< 2^16) spread to the even bit positions.
uint spread_bits(uint v) {
    v = (v | (v << 8)) & 0x00ff00ffu;
    v = (v | (v << 4)) & 0x0f0f0f0fu;
    v = (v | (v << 2)) & 0x33333333u;
    return (v | (v << 1)) & 0x55555555u;
}

// Inverse of spread_bits on the even bits of m.
uint compact_bits(uint m) {
    m &= 0x55555555u;
    m = (m | (m >> 1)) & 0x33333333u;
    m = (m | (m >> 2)) & 0x0f0f0f0fu;
    m = (m | (m >> 4)) & 0x00ff00ffu;
    return (m | (m >> 8)) & 0x0000ffffu;
}

void main() {
    const uint lid = gl_LocalInvocationID.x;
    const uint first = gl_WorkGroupID.x * SAMPLE_SORT_RAYS;
    const uint count = min(SAMPLE_SORT_RAYS, pc.n_rays - first);
    uint padded = 1u;
    while (padded < count) padded <<= 1;
    const uint64_t per_view = uint64_t(pc.width) * uint64_t(pc.height);
    const uint shift = 2u * pc.key_bits;

    for (uint t = lid; t < padded; t += gl_WorkGroupSize.x) {
        uint64_t key = ~0ul;
        if (t < count) {
            uint64_t p = splitmix64(pc.seed, first + t) % pc.n_pixels;
            uint64_t view = p / per_view;
            uint rest = uint(p - view * per_view);
            key = (view << shift) | uint64_t(spread_bits(rest % pc.width) | (spread_bits(rest / pc.width) << 1));
        }
        s_keys[t] = key;
    }
    barrier();

    // Bitonic sort of the padded run, ascending.
    for (uint k = 2u; k <= padded; k <<= 1) {
        for (uint j = k >> 1; j > 0u; j >>= 1) {
            for (uint t = lid; t < padded / 2u; t += gl_WorkGroupSize.x) {
                uint i = ((t & ~(j - 1u)) << 1) | (t & (j - 1u));
                uint64_t a = s_keys[i];
                uint64_t b = s_keys[i + j];
                if ((a > b) == ((i & k) == 0u)) {
                    s_keys[i] = b;
                    s_keys[i + j] = a;
                }
            }
            barrier();
        }
    }

    const uint64_t coord_mask = (uint64_t(1) << shift) - 1ul;
    for (uint t = lid; t < count; t += gl_WorkGroupSize.x) {
        uint64_t key = s_keys[t];
        uint r = first + t;
        pc.keys.v[r] = key;
        uint view = uint(key >> shift);
        uint morton = uint(key & coord_mask);
        uint x = compact_bits(morton);
        uint y = compact_bits(morton >> 1);
        SampleCamera c = pc.cams.v[view];
        float dx = (float(x) + 0.5 - c.centre.x) / c.focal.x;
        float dy = -((float(y) + 0.5 - c.centre.y) / c.focal.y);
        // R·(dx, dy, −1), summed in data::Camera's order (glam's transform_vector3).
        precise vec3 d = c.x_axis * dx + c.y_axis * dy + c.z_axis * -1.0;
        precise float len2 = d.x * d.x + d.y * d.y + d.z * d.z;
        d = d * (1.0 / sqrt(len2));
        pc.rays.v[6u * r + 0u] = c.origin.x;
        pc.rays.v[6u * r + 1u] = c.origin.y;
        pc.rays.v[6u * r + 2u] = c.origin.z;
        pc.rays.v[6u * r + 3u] = d.x;
        pc.rays.v[6u * r + 4u] = d.y;
        pc.rays.v[6u * r + 5u] = d.z;
        uint64_t pixel = uint64_t(view) * per_view + uint64_t(y * pc.width + x);
        uint px = U32Buf(uint64_t(pc.pixels) + 4ul * pixel).v[0];
        pc.targets.v[3u * r + 0u] = float(px & 0xffu) / 255.0;
        pc.targets.v[3u * r + 1u] = float((px >> 8) & 0xffu) / 255.0;
        pc.targets.v[3u * r + 2u] = float((px >> 16) & 0xffu) / 255.0;
    }
}
