// background.glsl — what a ray meets behind the grid (src/abi/buffers.rs `Background`: a
// colour, and spheres in front of it when `spheres` ≠ 0) and the learned background's gradient.
// Needs GL_EXT_shader_atomic_float and a `Background` buffer reference.
// Rust twin: math::background_msi::BackgroundView::behind; the per-ray Σ dL/dC·T·T_L of
// cpu::plenoxel_train::train and cpu::surface_train::train.
#ifndef BACKGROUND_GLSL
#define BACKGROUND_GLSL
#extension GL_KHR_shader_subgroup_arithmetic : require
#extension GL_KHR_shader_subgroup_basic : require
#include "background_msi.glsl"

// The background B behind the ray (o, unit d) and the weight T_L of the colour in it (rgb and 1
// without spheres).
vec3 background_behind(Background b, vec3 o, vec3 d, out float t_bg) {
    uint64_t a = packUint2x32(b.spheres);
    if (a == 0ul) {
        t_bg = 1.0;
        return b.rgb;
    }
    return bg_msi_composite(BackgroundSpheresBuf(a).v[0], o, d, b.rgb, t_bg);
}

#ifdef BG_MSI_BACKWARD
// Adds the spheres' texel gradient of the ray when they are learned (dL/dB = g, B = behind).
void background_spheres_grad(Background b, vec3 o, vec3 d, vec3 behind, vec3 g) {
    uint64_t a = packUint2x32(b.spheres);
    if (a == 0ul) return;
    BackgroundSpheres s = BackgroundSpheresBuf(a).v[0];
    if (s.learn != 0u) bg_msi_backward(s, o, d, behind, g);
}
#endif

// BUF.v[0].grad += G (vec3: this ray's dL/dC·T) summed over the subgroup first: one float atomic
// per subgroup and channel instead of one per ray on the same three words. A macro, as the
// counters' SUBGROUP_ADD (buffer references passed to functions become invalid SPIR-V).
#define BACKGROUND_GRAD_ADD(BUF, G) {                                                   \
    vec3 s_ = subgroupAdd(G);                                                           \
    if (subgroupElect()) {                                                              \
        atomicAdd((BUF).v[0].grad.x, s_.x);                                             \
        atomicAdd((BUF).v[0].grad.y, s_.y);                                             \
        atomicAdd((BUF).v[0].grad.z, s_.z);                                             \
    }                                                                                   \
}

#endif
