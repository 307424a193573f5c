#version 460
// surface_delta_tv — Lδ, the TV on δ over every allocated vertex (method.md §3.4), as two gather
// passes over the vertex rows with the per-grid axis-neighbour table nbr (6 rows per vertex:
// +x, +y, +z, −x, −y, −z; −1 outside the grid or unallocated); no slot arithmetic, no links:
// - stage 0: q[v] = d/√(|d|² + 1e-9), d the forward differences of δ from v to its +x, +y, +z
//   neighbours (0 where there is none);
// - stage 1: grad[v] += scale·(Σ_a q[v − e_a][a] − (q[v].x + q[v].y + q[v].z)) over the backward
//   neighbours that exist (plain read-modify-write: one owner per element).
// That is ∂(scale·Σ_v √(|d_v|² + 1e-9))/∂δ (scale = λ·κ/#vertices, cpu::surface_reg::
// delta_tv_chunk). Nothing is flagged touched: every vertex gets a δ gradient, and δ is then
// updated by surface_rmsprop's dense pass.
// Thread mapping: one invocation per vertex row v < rows.
// Inputs: nbr, delta, q (stage 1), rows, stage, scale. Outputs: q (stage 0, 3 floats per row),
// grad (stage 1). CPU twin: cpu::surface_delta_tv.
#include "common.glsl"
layout(local_size_x = 64) in;

layout(push_constant, scalar) uniform Push {
    I32Buf nbr;
    F32Buf delta;
    F32Buf q;
    F32Buf grad;
    uint rows;
    uint stage;
    float scale;
} pc;

void main() {
    uint v = flat_id();
    if (v >= pc.rows) return;
    if (pc.stage == 0u) {
        float d0 = pc.delta.v[v];
        vec3 d;
        for (uint a = 0u; a < 3u; a++) {
            int n = pc.nbr.v[6u * v + a];
            d[a] = n >= 0 ? pc.delta.v[uint(n)] - d0 : 0.0;
        }
        precise float tv = sqrt(((d.x * d.x + d.y * d.y) + d.z * d.z) + 1e-9);
        for (uint a = 0u; a < 3u; a++) {
            precise float qa = d[a] / tv;
            pc.q.v[3u * v + a] = qa;
        }
        return;
    }
    precise float back = 0.0;
    for (uint a = 0u; a < 3u; a++) {
        int m = pc.nbr.v[6u * v + 3u + a];
        if (m >= 0) back += pc.q.v[3u * uint(m) + a];
    }
    precise float own = (pc.q.v[3u * v] + pc.q.v[3u * v + 1u]) + pc.q.v[3u * v + 2u];
    precise float g = pc.grad.v[v] + pc.scale * (back - own);
    pc.grad.v[v] = g;
}
