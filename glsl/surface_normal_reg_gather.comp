#version 460
// surface_normal_reg_gather — pass 3 of 3 of the stage-2 normal regularisers Ln1 + Ln2 (method.md
// §3.4; definition in surface_normal_reg_pairs, layouts in normal_reg.glsl): each vertex gathers
// ∂L/∂δ from the cells it is a corner of. Vertex v (row r) is corner b (b = 4·x + 2·y + z bits)
// of the cell v − b: sum = Σ_{b = 0..7 in order} corners[8·(v − b) + b] over the cells v − b that
// are rows (nbr ≥ 0) among the `window` rows from start (the cells the pairs pass wrote this
// time) and in a kept pair (their corners are not +∞).
// Touched semantics (as the single-pass kernel had them): v is touched exactly when one of its
// cells is in a kept pair (either cell of a pair whose normals both have a direction), even if
// the sum is 0 (e.g. L1 alone with identical normals).
// Thread mapping: flat id = i < work, one vertex each, row r = corner_rows[range_row(first, i,
// n_corners)] (static ascending list of the corners of the existing cells, NormalPrefix::
// corner_rows; (first, work): the range of the corners of the window's cells, NormalChunk::
// corners_work); one owner per gradient element, no atomics.
// Inputs: corner_rows, n_corners, first, work, nbr (rows of v − b), corners (pass 2), rows,
// start (< rows), window (≤ rows), touch_bits.
// Outputs: for each touched v: grad[r] += sum (plain read-modify-write) and touch_mask(r,
// touch_bits) (step.glsl; touch_bits = 0 sets nothing).
// CPU twin: `cpu::surface_normal_reg_gather::normal_gather`.
#include "common.glsl"
#include "normal_reg.glsl"
#extension GL_EXT_control_flow_attributes : require
layout(local_size_x = 64) in;

layout(push_constant, scalar) uniform Push {
    U32Buf corner_rows;
    U64Buf nbr;
    F32Buf corners;
    F32Buf grad;
    StepRecord step;
    uint n_corners;
    uint first;
    uint work;
    uint rows;
    uint start;
    uint window;
    uint touch_bits;
} pc;

#include "step.glsl"

void main() {
    uint i = flat_id();
    if (i >= pc.work) return;
    uint r = pc.corner_rows.v[range_row(pc.first, i, pc.n_corners)];
    // l[b] = the row of v − b.
    int l[8];
    [[unroll]] for (uint w = 0u; w < 4u; w++) {
        ivec2 e = nbr_word(r, 4u + w);
        if (w != 0u) l[NBR_B[2u * w]] = e.x;
        l[NBR_B[2u * w + 1u]] = e.y;
    }
    l[0] = int(r);
    precise float sum = 0.0;
    bool touched = false;
    [[unroll]] for (uint b = 0u; b < 8u; b++) {
        if (l[b] < 0) continue;
        uint lb = uint(l[b]);
        if (!range_contains(pc.start, pc.window, pc.rows, lb)) continue;
        float c = pc.corners.v[8u * uint(l[b]) + b];
        if (floatBitsToUint(c) == NO_PAIR_BITS) continue;
        touched = true;
        sum += c;
    }
    if (!touched) return;
    pc.grad.v[r] += sum;
    touch_mask(r, pc.touch_bits);
}
