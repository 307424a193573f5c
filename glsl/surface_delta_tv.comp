#version 460
// surface_delta_tv — Lδ, the TV on δ over a chunk of the vertex rows (method.md §3.4; the chunk
// is rows (start + i) mod rows, i < count ≤ rows: every row in the paper preset, a random chunk
// in the fast one), as two gather passes with the per-grid axis-neighbour table nbr (6 rows per
// vertex: +x, +y, +z, −x, −y, −z; −1 outside the grid or unallocated); no slot arithmetic, no
// links:
// - stage 0, i < count, v = row i of the chunk: q[v] = d/√(|d|² + 1e-9), d the forward
//   differences of δ from v to its +x, +y, +z neighbours (0 where there is none); the other
//   rows' q are left as they are and never read;
// - stage 1, i < window, v = row i from start (the chunk and the rows its vertices' forward
//   neighbours can be, cpu::surface_delta_tv::forward_reach): grad[v] += scale·(Σ_a q[v − e_a][a]
//   − (q[v].x + q[v].y + q[v].z)), each sum over its terms whose vertex (v − e_a, or v) is in the
//   chunk (plain read-modify-write of grad: one owner per element).
// That is ∂(scale·Σ_{v in chunk} √(|d_v|² + 1e-9))/∂δ (scale = λ·κ/count,
// cpu::surface_reg::delta_tv_chunk). Nothing is flagged touched: surface_rmsprop's range pass
// updates δ on every row of the window.
// Thread mapping: one invocation per chunk row (stage 0) or window row (stage 1).
// Inputs: nbr, delta, q (stage 1), rows, stage, start (< rows), count, window (≤ rows), scale.
// Outputs: q (stage 0, 3 floats per row), grad (stage 1).
// CPU twin: cpu::surface_delta_tv.
#include "common.glsl"
layout(local_size_x = 64) in;

layout(push_constant, scalar) uniform Push {
    I32Buf nbr;
    F32Buf delta;
    F32Buf q;
    F32Buf grad;
    uint rows;
    uint stage;
    uint start;
    uint count;
    uint window;
    float scale;
} pc;

// Row i from the chunk's start (i < rows), and whether row v is in the chunk.
uint chunk_row(uint i) {
    return range_row(pc.start, i, pc.rows);
}

bool in_chunk(uint v) {
    return range_contains(pc.start, pc.count, pc.rows, v);
}

void main() {
    uint i = flat_id();
    if (pc.stage == 0u) {
        if (i >= pc.count) return;
        uint v = chunk_row(i);
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
    if (i >= pc.window) return;
    uint v = chunk_row(i);
    precise float back = 0.0;
    bool any = false;
    for (uint a = 0u; a < 3u; a++) {
        int m = pc.nbr.v[6u * v + 3u + a];
        if (m >= 0 && in_chunk(uint(m))) {
            back += pc.q.v[3u * uint(m) + a];
            any = true;
        }
    }
    precise float own = 0.0;
    if (in_chunk(v)) {
        own = (pc.q.v[3u * v] + pc.q.v[3u * v + 1u]) + pc.q.v[3u * v + 2u];
        any = true;
    }
    if (!any) return;
    precise float g = pc.grad.v[v] + pc.scale * (back - own);
    pc.grad.v[v] = g;
}
