#version 460
// background_spheres_step — one RMSProp step of a background's sphere texels
// (src/abi/buffers.rs `BackgroundSpheres`), after the training kernel of the step has added
// their gradient: for every value whose gradient is nonzero (values no ray reached keep their
// running average, as svox2's sparse step) r ← (r == 0 ? g² : β·r + (1 − β)·g²);
// v ← v − lr·g/(√r + ε), lr = lr_sigma for σ (the first of a texel's four values), lr_colour for
// the colour; g ← 0. Unclamped: the renderers clamp σ and the colour at 0 (background_msi.glsl).
// Thread mapping: one invocation per value.
// CPU twin: `cpu::background_spheres_step::background_spheres_step`.
#include "common.glsl"
#include "rmsprop.glsl"
layout(local_size_x = 64) in;

layout(push_constant, scalar) uniform Push {
    BackgroundSpheresBuf spheres;
    F32Buf avg;
    float lr_sigma;
    float lr_colour;
    float beta;
    float eps;
    uint n;
} pc;

void main() {
    uint i = flat_id();
    if (i >= pc.n) return;
    BackgroundSpheres s = pc.spheres.v[0];
    F32Buf table = F32Buf(packUint2x32(s.table));
    F32Buf grad = F32Buf(packUint2x32(s.grad));
    if (grad.v[i] == 0.0) return;
    RMSPROP_UPDATE(table, grad, pc.avg, i, i % 4u == 0u ? pc.lr_sigma : pc.lr_colour);
}
