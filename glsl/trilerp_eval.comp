#version 460
// trilerp_eval — evaluates glsl/lib/trilerp.glsl on test cases.
// Thread mapping: one invocation per case.
// Inputs: `corners` (8 floats per case, order 000..111), `points` (3 floats per case, p ∈ [0,1]³).
// Output: `out_` (12 floats per case): value, ∂/∂x, ∂/∂y, ∂/∂z, then the 8 trilinear weights.
// CPU twin: `cpu::trilerp_eval`.
#include "common.glsl"
#include "trilerp.glsl"
layout(local_size_x = 64) in;

layout(push_constant, scalar) uniform Push {
    F32Buf corners;
    F32Buf points;
    F32Buf out_;
    uint n;
} pc;

void main() {
    uint i = flat_id();
    if (i >= pc.n) return;
    float c[8];
    for (int j = 0; j < 8; j++) c[j] = pc.corners.v[8 * i + j];
    vec3 p = vec3(pc.points.v[3 * i], pc.points.v[3 * i + 1], pc.points.v[3 * i + 2]);
    vec4 g = trilerp_grad(c, p);
    float w[8];
    trilerp_weights(p, w);
    uint b = 12 * i;
    pc.out_.v[b] = g.x;
    pc.out_.v[b + 1] = g.y;
    pc.out_.v[b + 2] = g.z;
    pc.out_.v[b + 3] = g.w;
    for (int j = 0; j < 8; j++) pc.out_.v[b + 4 + j] = w[j];
}
