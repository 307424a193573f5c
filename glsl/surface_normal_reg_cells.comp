#version 460
// surface_normal_reg_cells — pass 1 of 3 of the stage-2 normal regularisers Ln1 + Ln2 (method.md
// §3.4; definition in surface_normal_reg_pairs, layouts in normal_reg.glsl): the normal and
// status of every cell. A cell is named by its lower corner vertex v (row r); it exists when it
// lies inside the grid and its 8 corners are allocated (nbr[r][j] ≥ 0 for j = 1..7). Its normal
// is n = (Σ_{b,c} δ_1bc − Σ_{b,c} δ_0bc, likewise for y and z)/4 (corner b = 4·x + 2·y + z bits).
// The cells of the chunk's window (its rows and the cells' forward reach after them,
// cpu::surface_reg::NormalChunk::window), not only the chunk's: the pairs pass reads the forward
// neighbours of the chunk's cells. The other cells' entries are left as they were (the pairs
// pass reads none of them); the cells that do not exist keep normals[r] = 0 (status 0) from the
// buffer's creation.
// Thread mapping: flat id = i < work, one existing cell each, row r = cell_rows[range_row(first,
// i, n_cells)] (cell_rows: a static ascending list of the existing cells, built once per grid on
// the host: NormalPrefix::cell_rows; (first, work): the window's range of it, NormalChunk::
// cells_work); one owner per written element.
// Inputs: cell_rows, n_cells, first, work, nbr (rows of the corners, k), delta.
// Outputs: normals[r] = (n, status + 4·k) (plain stores).
// CPU twin: `cpu::surface_normal_reg_cells::normal_cells`.
#include "common.glsl"
#include "normal_reg.glsl"
#extension GL_EXT_control_flow_attributes : require
layout(local_size_x = 64) in;

layout(push_constant, scalar) uniform Push {
    U32Buf cell_rows;
    U64Buf nbr;
    F32Buf delta;
    Vec4Buf normals;
    uint n_cells;
    uint first;
    uint work;
} pc;

void main() {
    uint i = flat_id();
    if (i >= pc.work) return;
    uint r = pc.cell_rows.v[range_row(pc.first, i, pc.n_cells)];
    // l[b] = the row of corner b.
    int l[8];
    uint k = 0u;
    [[unroll]] for (uint w = 0u; w < 4u; w++) {
        ivec2 e = nbr_word(r, w);
        if (w == 0u) {
            k = uint(e.x);
        } else {
            l[NBR_B[2u * w]] = e.x;
        }
        l[NBR_B[2u * w + 1u]] = e.y;
    }
    l[0] = int(r);
    float d[8];
    [[unroll]] for (uint b = 0u; b < 8u; b++) d[b] = pc.delta.v[l[b]];
    precise float mx = ((d[4] + d[5]) + (d[6] + d[7])) - ((d[0] + d[1]) + (d[2] + d[3]));
    precise float my = ((d[2] + d[3]) + (d[6] + d[7])) - ((d[0] + d[1]) + (d[4] + d[5]));
    precise float mz = ((d[1] + d[3]) + (d[5] + d[7])) - ((d[0] + d[2]) + (d[4] + d[6]));
    vec3 n = vec3(mx, my, mz) * 0.25;
    precise float n2 = (n.x * n.x + n.y * n.y) + n.z * n.z;
    pc.normals.v[r] = pack4(vec4(n, float((n2 <= TINY_NORMAL2 ? 1u : 2u) + 4u * k)));
}
