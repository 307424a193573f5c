#version 460
// cubic_solve — closed-form ray/level-set crossings in one cell, one case per invocation.
// Thread mapping: one invocation per case (flat 1-D index over a 2-D grid).
// Inputs: `cases`, 16 floats per case: corners[8] (paper order, index 4a + 2b + c), o'[3], d[3],
// L, tau. Outputs: `count[i]` (0..3), `s[3i + k]` and `rising[3i + k]` (0/1) for k < count[i];
// unused slots are written as 0. CPU twin: `cpu::cubic_solve::cubic_solve`.
#include "common.glsl"
#include "cubic.glsl"
layout(local_size_x = 64) in;

layout(push_constant, scalar) uniform Push {
    F32Buf cases;
    U32Buf count;
    F32Buf s;
    U32Buf rising;
    uint n;
} pc;

void main() {
    uint i = flat_id();
    if (i >= pc.n) return;
    uint base = 16u * i;
    float c[8] = float[8](pc.cases.v[base], pc.cases.v[base + 1u], pc.cases.v[base + 2u],
                          pc.cases.v[base + 3u], pc.cases.v[base + 4u], pc.cases.v[base + 5u],
                          pc.cases.v[base + 6u], pc.cases.v[base + 7u]);
    vec3 o = vec3(pc.cases.v[base + 8u], pc.cases.v[base + 9u], pc.cases.v[base + 10u]);
    vec3 d = vec3(pc.cases.v[base + 11u], pc.cases.v[base + 12u], pc.cases.v[base + 13u]);
    float L = pc.cases.v[base + 14u];
    float tau = pc.cases.v[base + 15u];
    CubicCrossings x = cubic_solve(cubic_cell(c, o, d), cubic_level_ends(c, o, d, L, tau), L, 0.0);
    pc.count.v[i] = x.n;
    pc.s.v[3u * i] = x.s.x;
    pc.s.v[3u * i + 1u] = x.s.y;
    pc.s.v[3u * i + 2u] = x.s.z;
    pc.rising.v[3u * i] = x.rising & 1u;
    pc.rising.v[3u * i + 1u] = (x.rising >> 1) & 1u;
    pc.rising.v[3u * i + 2u] = (x.rising >> 2) & 1u;
}
