#version 460
// background_msi_eval — evaluates glsl/lib/background_msi.glsl on test rays.
// Thread mapping: one invocation per ray.
// Inputs: `spheres` (BackgroundSpheres: geometry, the table's and its gradient's addresses),
// `rays` (6 floats per ray: origin, unit direction), `upstream` (3 floats per ray: dL/dB),
// `rgb` (the colour behind the spheres).
// Outputs: `out_` (4 floats per ray: B, then T_L); the table's gradient += (float atomics).
// CPU twin: `cpu::background_msi_eval`.
#extension GL_EXT_shader_atomic_float : require
#define BG_MSI_BACKWARD
#include "common.glsl"
#include "background_msi.glsl"
layout(local_size_x = 64) in;

layout(push_constant, scalar) uniform Push {
    BackgroundSpheresBuf spheres;
    F32Buf rays;
    F32Buf upstream;
    F32Buf out_;
    vec3 rgb;
    uint n;
} pc;

void main() {
    uint r = flat_id();
    if (r >= pc.n) return;
    BackgroundSpheres s = pc.spheres.v[0];
    vec3 o = vec3(pc.rays.v[6u * r], pc.rays.v[6u * r + 1u], pc.rays.v[6u * r + 2u]);
    vec3 d = vec3(pc.rays.v[6u * r + 3u], pc.rays.v[6u * r + 4u], pc.rays.v[6u * r + 5u]);
    vec3 g = vec3(pc.upstream.v[3u * r], pc.upstream.v[3u * r + 1u], pc.upstream.v[3u * r + 2u]);
    float t;
    vec3 b = bg_msi_composite(s, o, d, pc.rgb, t);
    pc.out_.v[4u * r] = b.x;
    pc.out_.v[4u * r + 1u] = b.y;
    pc.out_.v[4u * r + 2u] = b.z;
    pc.out_.v[4u * r + 3u] = t;
    bg_msi_backward(s, o, d, b, g);
}
