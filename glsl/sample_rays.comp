#version 460
// sample_rays — draws a batch of training rays on the device (CPU twin: `cpu::sample_rays::sample_rays`), in
// three dispatches (gpu::TrainViewBuffers::record_sample): pass 0 of this kernel, then
// sample_rays_sort, then pass 1 of this kernel; the parity row checks the whole draw.
// Ray i of the batch hashes h = splitmix64(seed + (i + 1)·γ) (a counter-based draw: no state
// between batches) and picks pixel h mod n_pixels over all pixels of the split (uniform with
// replacement) or, when the high 32 bits of h are below focus_threshold, the focus pixel
// focus[h mod n_focus] (abi::rays::Focus: a share of the batch from the pixels the object
// covers), as the
// key (view << 2·key_bits) | morton(x, y), which determines the pixel. Each run of
// SAMPLE_SORT_RAYS rays is sorted by key (the last run may be shorter), so within a run the rays
// are ordered by view and Z-order (neighbouring invocations of the training kernels trace nearby
// rays); equal keys are equal pixels, so the sorted run is unique.
// Thread mapping (both passes): one invocation per ray, flat_id() = its index in the batch.
// Pass 0 draws ray i's key into scratch; sample_rays_sort sorts scratch into keys; pass 1 writes
// the ray of the key at its position: origin = the view's camera centre in the scaled world, unit
// direction = normalize(R·((x + ½ − cx)/fx, −(y + ½ − cy)/fy, −1)) as data::Camera::pixel_ray,
// target = the pixel's composited RGB / 255; for a forward-facing capture in NDC (ndc_near > 0)
// that ray carried into NDC (lib/ndc.glsl).
// Inputs: pixels (RGBA8 packed in a u32 per pixel, views × height × width, row-major), cams
// (SampleCamera per view), focus (flat pixel indices, ascending; unread when focus_threshold is
// 0), keys (pass 1). Outputs: scratch (the drawn keys, pass 0), rays (6
// floats), targets (3 floats) and, with a focus, weights (pass 1: the ray's importance weight,
// w_focus for a focus pixel, found by binary search, else w_other).
#include "common.glsl"
#include "ndc.glsl"
layout(local_size_x = 256) in;

layout(push_constant, scalar) uniform Push {
    U32Buf pixels;
    SampleCameraBuf cams;
    F32Buf rays;
    F32Buf targets;
    U64Buf keys;
    U64Buf scratch;
    U32Buf focus;
    F32Buf weights;
    uint64_t seed;
    uint64_t n_pixels;
    uint width;
    uint height;
    uint n_rays;
    // Bits of a pixel coordinate: max(width, height) − 1 < 2^key_bits ≤ 2^16.
    uint key_bits;
    uint pass;
    uint n_focus;
    uint focus_threshold;
    float w_focus;
    float w_other;
    // The NDC map (near, sx, sy; lib/ndc.glsl) of a forward-facing capture, the cameras given in
    // its frame; near = 0: rays stay in the scaled world.
    float ndc_near;
    float ndc_sx;
    float ndc_sy;
} pc;

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

void draw() {
    const uint r = flat_id();
    if (r >= pc.n_rays) return;
    const uint64_t per_view = uint64_t(pc.width) * uint64_t(pc.height);
    const uint64_t h = splitmix64(pc.seed, r);
    uint64_t p;
    if (uint(h >> 32) < pc.focus_threshold) {
        p = uint64_t(pc.focus.v[uint(h % uint64_t(pc.n_focus))]);
    } else {
        p = h % pc.n_pixels;
    }
    uint64_t view = p / per_view;
    uint rest = uint(p - view * per_view);
    uint morton = spread_bits(rest % pc.width) | (spread_bits(rest / pc.width) << 1);
    pc.scratch.v[r] = (view << (2u * pc.key_bits)) | uint64_t(morton);
}

// Two floats from a 64-bit word (low word first, as in memory).
vec2 floats(uint64_t w) {
    return uintBitsToFloat(unpackUint2x32(w));
}

// The 64-bit word of floats a, b.
uint64_t word(float a, float b) {
    return packUint2x32(floatBitsToUint(vec2(a, b)));
}

void write_ray() {
    const uint at = flat_id();
    if (at >= pc.n_rays) return;
    const uint64_t key = pc.keys.v[at];
    const uint shift = 2u * pc.key_bits;
    const uint64_t coord_mask = (uint64_t(1) << shift) - 1ul;
    uint view = uint(key >> shift);
    uint morton = uint(key & coord_mask);
    uint x = compact_bits(morton);
    uint y = compact_bits(morton >> 1);
    // The view's SampleCamera (16 floats, 64 bytes: the host checks) as 8 words: lavapipe loads and stores memory one
    // component at a time, so pairs halve this pass's memory operations (as the ray's below).
    U64Buf cw = U64Buf(uint64_t(pc.cams) + 64ul * uint64_t(view));
    vec2 w0 = floats(cw.v[0]), w1 = floats(cw.v[1]), w2 = floats(cw.v[2]), w3 = floats(cw.v[3]);
    vec2 w4 = floats(cw.v[4]), w5 = floats(cw.v[5]), focal = floats(cw.v[6]), centre = floats(cw.v[7]);
    vec3 x_axis = vec3(w0, w1.x), y_axis = vec3(w1.y, w2), z_axis = vec3(w3, w4.x);
    vec3 origin = vec3(w4.y, w5);
    float dx = (float(x) + 0.5 - centre.x) / focal.x;
    float dy = -((float(y) + 0.5 - centre.y) / focal.y);
    // R·(dx, dy, −1), summed in data::Camera's order (glam's transform_vector3).
    precise vec3 d = x_axis * dx + y_axis * dy + z_axis * -1.0;
    precise float len2 = d.x * d.x + d.y * d.y + d.z * d.z;
    d = d * (1.0 / sqrt(len2));
    if (pc.ndc_near > 0.0) {
        ndc_ray(origin, d, vec3(pc.ndc_near, pc.ndc_sx, pc.ndc_sy), origin, d);
    }
    U64Buf rw = U64Buf(uint64_t(pc.rays) + 24ul * uint64_t(at));
    rw.v[0] = word(origin.x, origin.y);
    rw.v[1] = word(origin.z, d.x);
    rw.v[2] = word(d.y, d.z);
    const uint64_t per_view = uint64_t(pc.width) * uint64_t(pc.height);
    uint64_t pixel = uint64_t(view) * per_view + uint64_t(y * pc.width + x);
    uint px = U32Buf(uint64_t(pc.pixels) + 4ul * pixel).v[0];
    if (pc.focus_threshold != 0u) {
        // Lower bound of the pixel in the ascending focus table.
        uint lo = 0u, hi = pc.n_focus;
        while (lo < hi) {
            uint mid = lo + (hi - lo) / 2u;
            if (uint64_t(pc.focus.v[mid]) < pixel) {
                lo = mid + 1u;
            } else {
                hi = mid;
            }
        }
        bool hit = lo < pc.n_focus && uint64_t(pc.focus.v[lo]) == pixel;
        pc.weights.v[at] = hit ? pc.w_focus : pc.w_other;
    }
    pc.targets.v[3u * at + 0u] = float(px & 0xffu) / 255.0;
    pc.targets.v[3u * at + 1u] = float((px >> 8) & 0xffu) / 255.0;
    pc.targets.v[3u * at + 2u] = float((px >> 16) & 0xffu) / 255.0;
}

void main() {
    if (pc.pass == 0u) {
        draw();
    } else {
        write_ray();
    }
}
