// background.glsl — the learned background's gradient (src/abi/buffers.rs `Background`).
// Needs GL_EXT_shader_atomic_float and a `Background` buffer reference.
// Rust twin: the per-ray Σ dL/dC·T of cpu::plenoxel_train::train and cpu::surface_train::train.
#ifndef BACKGROUND_GLSL
#define BACKGROUND_GLSL
#extension GL_KHR_shader_subgroup_arithmetic : require
#extension GL_KHR_shader_subgroup_basic : require

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
