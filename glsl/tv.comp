#version 460
// tv — gradient of the total-variation regulariser on a contiguous chunk of vertex slots
// [start, start + count) (method.md §2): for each allocated slot u in the chunk and channel c,
// TV_u = √(Δx² + Δy² + Δz² + 1e-9) with forward differences to u + e_x, e_y, e_z (a neighbour that
// is outside the grid or unallocated counts as equal: Δ = 0); loss = scale·Σ TV_u.
// Gathered, not scattered: each invocation owns one (slot v, channel) and adds to grad[v] the
// derivative of TV_v and of the TVs of its backward neighbours v − e_a that lie in the chunk, so
// no atomics are needed. Slots range over [start, start + count + Y·Z) to reach those neighbours.
// Thread mapping: flat id = (slot − start)·channels + c.
// Inputs: links, data (channels floats per allocated vertex), res, chunk, scale (λ/count).
// Output: grad += (plain read-modify-write; one owner per element). CPU twin: cpu::tv.
#include "common.glsl"
layout(local_size_x = 256) in;

layout(push_constant, scalar) uniform Push {
    I32Buf links;
    F32Buf data;
    F32Buf grad;
    uvec3 res;
    uint start;
    uint count;
    uint channels;
    float scale;
} pc;

float value(int link, uint c) {
    return pc.data.v[uint(link) * pc.channels + c];
}

// Neighbour link of slot s along axis a (+1), or −1 when outside the grid.
int forward_link(uvec3 v, uint s, uint a) {
    uint stride = a == 0u ? pc.res.y * pc.res.z : (a == 1u ? pc.res.z : 1u);
    if (v[a] + 1u >= pc.res[a]) return -1;
    return pc.links.v[s + stride];
}

uvec3 slot_vertex(uint s) {
    return uvec3(s / (pc.res.y * pc.res.z), (s / pc.res.z) % pc.res.y, s % pc.res.z);
}

// Forward differences of slot s (allocated, link l) in channel c, and their TV norm.
vec4 tv_of(uint s, int l, uint c) {
    uvec3 v = slot_vertex(s);
    float v0 = value(l, c);
    vec3 d;
    for (uint a = 0u; a < 3u; a++) {
        int n = forward_link(v, s, a);
        d[a] = n >= 0 ? value(n, c) - v0 : 0.0;
    }
    precise float tv = sqrt(d.x * d.x + d.y * d.y + d.z * d.z + 1e-9);
    return vec4(d, tv);
}

void main() {
    uint id = flat_id();
    uint span = pc.count + pc.res.y * pc.res.z;
    if (id >= span * pc.channels) return;
    uint s = pc.start + id / pc.channels;
    uint c = id % pc.channels;
    uint slots = pc.res.x * pc.res.y * pc.res.z;
    if (s >= slots) return;
    int l = pc.links.v[s];
    if (l < 0) return;
    uint end = pc.start + pc.count;
    precise float g = 0.0;
    if (s < end) {
        vec4 own = tv_of(s, l, c);
        g -= (own.x + own.y + own.z) / own.w;
    }
    uvec3 v = slot_vertex(s);
    for (uint a = 0u; a < 3u; a++) {
        uint stride = a == 0u ? pc.res.y * pc.res.z : (a == 1u ? pc.res.z : 1u);
        if (v[a] == 0u) continue;
        uint u = s - stride;
        if (u < pc.start || u >= end) continue;
        int lu = pc.links.v[u];
        if (lu < 0) continue;
        vec4 tu = tv_of(u, lu, c);
        g += tu[a] / tu.w;
    }
    uint i = uint(l) * pc.channels + c;
    pc.grad.v[i] = pc.grad.v[i] + pc.scale * g;
}
