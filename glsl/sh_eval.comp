#version 460
// sh_eval — evaluates glsl/lib/sh.glsl on test cases.
// Thread mapping: one invocation per case.
// Inputs: `dirs` (3 floats per case, unit directions), `coefs` (27 floats per case,
// [R0..R8, G0..G8, B0..B8]).
// Output: `out_` (12 floats per case): Y_0..Y_8, then R, G, B. CPU twin: `cpu::sh_eval`.
#include "common.glsl"
#include "sh.glsl"
layout(local_size_x = 64) in;

layout(push_constant, scalar) uniform Push {
    F32Buf dirs;
    F32Buf coefs;
    F32Buf out_;
    uint n;
} pc;

void main() {
    uint i = flat_id();
    if (i >= pc.n) return;
    vec3 d = vec3(pc.dirs.v[3 * i], pc.dirs.v[3 * i + 1], pc.dirs.v[3 * i + 2]);
    float y[9];
    sh_basis(d, y);
    uint b = 12 * i;
    for (int k = 0; k < 9; k++) pc.out_.v[b + k] = y[k];
    for (int ch = 0; ch < 3; ch++) {
        float c[9];
        for (int k = 0; k < 9; k++) c[k] = pc.coefs.v[27 * i + 9 * ch + k];
        pc.out_.v[b + 9 + ch] = sh_channel(y, c);
    }
}
