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
//   neighbours can be, abi::regularisers::forward_reach): grad[v] += scale·(Σ_a q[v − e_a][a]
//   − (q[v].x + q[v].y + q[v].z)), each sum over its terms whose vertex (v − e_a, or v) is in the
//   chunk (plain read-modify-write of grad: one owner per element).
// That is ∂(scale·Σ_{v in chunk} √(|d_v|² + 1e-9))/∂δ (scale = λ·κ/count,
// abi::regularisers::delta_tv_chunk). Nothing is flagged touched: surface_rmsprop's range pass
// updates δ on every row of the window.
// Thread mapping: one invocation per chunk row (stage 0) or window row (stage 1).
// Inputs: nbr, delta, q (stage 1), rows, stage, start (< rows), count, window (≤ rows), scale.
// Outputs: q (stage 0, Q_FLOATS = 4 floats per row: x, y, z, 0), grad (stage 1).
// The table (6 entries per row) and q (4 floats per row) are read and written as aligned 64-bit
// words where a pair is wanted (lavapipe moves memory one component at a time).
// CPU twin: `cpu::surface_delta_tv::delta_tv`.
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

// Floats per row of q.

// Row i from the chunk's start (i < rows), and whether row v is in the chunk.
uint chunk_row(uint i) {
    return range_row(pc.start, i, pc.rows);
}

bool in_chunk(uint v) {
    return range_contains(pc.start, pc.count, pc.rows, v);
}

void main() {
    uint i = flat_id();
    // The table's 6 entries of a row as 3 aligned 64-bit words, q's row as 2 (U64Buf).
    U64Buf nbr2 = U64Buf(uint64_t(pc.nbr));
    U64Buf q2 = U64Buf(uint64_t(pc.q));
    if (pc.stage == 0u) {
        if (i >= pc.count) return;
        uint v = chunk_row(i);
        float d0 = pc.delta.v[v];
        uvec2 fxy = unpack32(nbr2.v[3u * v]);
        ivec3 fwd = ivec3(int(fxy.x), int(fxy.y), int(unpack32(nbr2.v[3u * v + 1u]).x));
        vec3 d;
        for (uint a = 0u; a < 3u; a++) {
            int n = fwd[a];
            d[a] = n >= 0 ? pc.delta.v[uint(n)] - d0 : 0.0;
        }
        precise float tv = sqrt(((d.x * d.x + d.y * d.y) + d.z * d.z) + 1e-9);
        precise vec3 q = d / tv;
        q2.v[2u * v] = pack64(floatBitsToUint(q.xy));
        q2.v[2u * v + 1u] = pack64(uvec2(floatBitsToUint(q.z), 0u));
        return;
    }
    if (i >= pc.window) return;
    uint v = chunk_row(i);
    uvec2 zx = unpack32(nbr2.v[3u * v + 1u]);
    uvec2 yz = unpack32(nbr2.v[3u * v + 2u]);
    ivec3 back_rows = ivec3(int(zx.y), int(yz.x), int(yz.y));
    precise float back = 0.0;
    bool any = false;
    for (uint a = 0u; a < 3u; a++) {
        int m = back_rows[a];
        if (m >= 0 && in_chunk(uint(m))) {
            back += pc.q.v[Q_FLOATS * uint(m) + a];
            any = true;
        }
    }
    precise float own = 0.0;
    if (in_chunk(v)) {
        vec2 qxy = uintBitsToFloat(unpack32(q2.v[2u * v]));
        float qz = pc.q.v[Q_FLOATS * v + 2u];
        own = (qxy.x + qxy.y) + qz;
        any = true;
    }
    if (!any) return;
    precise float g = pc.grad.v[v] + pc.scale * (back - own);
    pc.grad.v[v] = g;
}
