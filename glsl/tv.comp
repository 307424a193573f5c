#version 460
// tv — gradient of the total-variation regulariser on a contiguous chunk of vertex slots
// [start, start + count) (method.md §2): for each allocated slot u in the chunk and channel c,
// TV_u = √(Δx² + Δy² + Δz² + 1e-9) with forward differences to u + e_x, e_y, e_z (a neighbour that
// is outside the grid or unallocated counts as equal: Δ = 0); loss = scale·Σ TV_u.
// Gathered, not scattered: each invocation owns one slot v (all its channels) and adds to grad[v]
// the derivative of TV_v and of the TVs of its backward neighbours v − e_a that lie in the chunk,
// so no atomics are needed; the neighbour links are read once for all channels. Slots range over
// [start, start + count + Y·Z) to reach those neighbours.
// Thread mapping: flat id = slot − start.
// Inputs: links, data (channels floats per allocated vertex), res, chunk, scale (λ/count).
// Output: grad += (plain read-modify-write; one owner per element) for vertices with a TV term;
// each gets the touched bits touch_bits (0: none; step.glsl). CPU twin: `cpu::tv`.
#include "common.glsl"
layout(local_size_x = 256) in;

layout(push_constant, scalar) uniform Push {
    I32Buf links;
    F32Buf data;
    F32Buf grad;
    StepRecord step;
    uvec3 res;
    uint start;
    uint count;
    uint channels;
    float scale;
    uint touch_bits;
} pc;

#include "step.glsl"

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

// TV norm of forward differences d.
float tv_norm(vec3 d) {
    precise float tv = sqrt(d.x * d.x + d.y * d.y + d.z * d.z + 1e-9);
    return tv;
}

// Forward differences in channel c of a vertex with value link l and forward neighbour links n.
vec3 diffs(int l, int n[3], uint c) {
    float v0 = value(l, c);
    vec3 d;
    for (uint a = 0u; a < 3u; a++) {
        d[a] = n[a] >= 0 ? value(n[a], c) - v0 : 0.0;
    }
    return d;
}

void main() {
    uint span = pc.count + pc.res.y * pc.res.z;
    uint id = flat_id();
    if (id >= span) return;
    uint s = pc.start + id;
    uint slots = pc.res.x * pc.res.y * pc.res.z;
    if (s >= slots) return;
    int l = pc.links.v[s];
    if (l < 0) return;
    uint end = pc.start + pc.count;
    uvec3 v = slot_vertex(s);
    // The links every channel needs, read once: own forward neighbours when s is in the chunk, and
    // for each backward neighbour u = s − e_a in the chunk, u's link and forward neighbours.
    bool own = s < end;
    int own_n[3];
    for (uint a = 0u; a < 3u; a++) own_n[a] = own ? forward_link(v, s, a) : -1;
    int lu[3];
    int un[3][3];
    bool contributed = own;
    for (uint a = 0u; a < 3u; a++) {
        lu[a] = -1;
        uint stride = a == 0u ? pc.res.y * pc.res.z : (a == 1u ? pc.res.z : 1u);
        if (v[a] == 0u || s - stride < pc.start || s - stride >= end) continue;
        uint u = s - stride;
        lu[a] = pc.links.v[u];
        if (lu[a] < 0) continue;
        contributed = true;
        uvec3 vu = v;
        vu[a] -= 1u;
        for (uint b = 0u; b < 3u; b++) un[a][b] = forward_link(vu, u, b);
    }
    if (!contributed) return;
    for (uint c = 0u; c < pc.channels; c++) {
        precise float g = 0.0;
        if (own) {
            vec3 d = diffs(l, own_n, c);
            g -= (d.x + d.y + d.z) / tv_norm(d);
        }
        for (uint a = 0u; a < 3u; a++) {
            if (lu[a] < 0) continue;
            vec3 d = diffs(lu[a], un[a], c);
            g += d[a] / tv_norm(d);
        }
        uint i = uint(l) * pc.channels + c;
        pc.grad.v[i] = pc.grad.v[i] + pc.scale * g;
    }
    touch_mask(uint(l), pc.touch_bits);
}
