// normal_reg.glsl — what the three passes of the stage-2 normal regularisers Ln1 + Ln2 share
// (method.md §3.4; surface_normal_reg_cells, _pairs, _gather): buffer types, the per-row arrays
// and their layouts. A cell is named by its lower corner vertex, so a cell is a vertex row r and
// every array is indexed by row.
// lavapipe loads and stores global memory one component of one invocation at a time, so the
// arrays are read and written as 64-bit words: a vec4 moved as two 64-bit components costs half
// as much as four floats.
//   nbr (NBR_WORDS words = 16 ints per row; static, built once per grid on the host by
//     cpu::surface_reg::normal_neighbours): [0] = k, the number of existing forward neighbour
//     cells of the cell (0 when it does not exist); [j] for j = 1..7 = the row of vertex
//     v + NBR_B[j] and [8 + j] = the row of v − NBR_B[j] (b = 4·x + 2·y + z bits; −1 outside the
//     grid or unallocated); [8] unused (−1). NBR_B puts the face neighbours (z, y, x) first, so
//     that they take two words. Entries 2w and 2w + 1 are the low and high halves of word w.
//   normals[r] (vec4): (n, status + 4·k); n = the cell's unnormalised normal; status 0 = the cell
//     does not exist (outside the grid, or a corner unallocated), 1 = tiny normal
//     (|n|² ≤ TINY_NORMAL2), 2 = a direction.
//   corners[8·r + b] (floats, written as 4 words): for a cell in a kept pair, ∂L/∂δ of its
//     corner b, corner_grad(b, ∂L/∂n); +∞ for every other cell (the gather skips those).
// Include before the push block. Rust twin: cpu::surface_reg (normal_neighbours, normal_cells,
// normal_pairs, normal_gather).
#ifndef NORMAL_REG_GLSL
#define NORMAL_REG_GLSL

layout(buffer_reference, scalar, buffer_reference_align = 16) buffer Vec4Buf { u64vec2 v[]; };

// NBR_STRIDE (ints per row), NBR_B (the corner offset b of table entry j and 8 + j) and
// TINY_NORMAL2: src/abi/consts.rs (abi.glsl).
const uint NBR_WORDS = NBR_STRIDE / 2u;
// The corner slots of a cell in no kept pair: +∞.
const uint NO_PAIR_BITS = 0x7f800000u;

vec4 unpack4(u64vec2 p) {
    return vec4(uintBitsToFloat(unpackUint2x32(p.x)), uintBitsToFloat(unpackUint2x32(p.y)));
}

u64vec2 pack4(vec4 x) {
    return u64vec2(packUint2x32(floatBitsToUint(x.xy)), packUint2x32(floatBitsToUint(x.zw)));
}

// Entries 2w and 2w + 1 of row r's neighbour table (needs a push block `pc` with `U64Buf nbr`).
#define nbr_word(r, w) ivec2(unpackUint2x32(pc.nbr.v[NBR_WORDS * (r) + (w)]))

// The status and k of a normals entry.
uint cell_status(vec4 n) {
    return uint(n.w) & 3u;
}

uint cell_k(vec4 n) {
    return uint(n.w) >> 2u;
}

#endif
