#version 460
// cubic_solve — closed-form ray/level-set crossings in one cell, one case per invocation.
// Thread mapping: one invocation per case (flat 1-D index over a 2-D grid).
// Inputs: `cases`, 16 floats per case: corners[8] (paper order, index 4a + 2b + c), o'[3], d[3],
// L, tau. Outputs: `count[i]` (0..3), `s[3i + k]` and `rising[3i + k]` (0/1) for k < count[i];
// unused slots are written as 0. CPU twin: `cpu::cubic_solve` (src/cpu/cubic_solve.rs).
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
    float c[8];
    for (uint k = 0u; k < 8u; ++k) c[k] = pc.cases.v[base + k];
    vec3 o = vec3(pc.cases.v[base + 8u], pc.cases.v[base + 9u], pc.cases.v[base + 10u]);
    vec3 d = vec3(pc.cases.v[base + 11u], pc.cases.v[base + 12u], pc.cases.v[base + 13u]);
    float L = pc.cases.v[base + 14u];
    float tau = pc.cases.v[base + 15u];
    Crossings x = cubic_solve(cubic_cell(c, o, d), cubic_level_ends(c, o, d, L, tau), L);
    pc.count.v[i] = x.n;
    for (uint k = 0u; k < 3u; ++k) {
        pc.s.v[3u * i + k] = k < x.n ? x.s[k] : 0.0;
        pc.rising.v[3u * i + k] = (x.rising >> k) & 1u;
    }
}
