#version 460
// surface_normal_reg_pairs — pass 2 of 3 of the stage-2 normal regularisers Ln1 + Ln2 (method.md
// §3.4): the loss, and each cell's ∂L/∂n from the pairs it is in. Definition: with the cell
// normals n of pass 1 (surface_normal_reg_cells) and N = n/|n|, for each existing cell c of the
// chunk and each existing forward neighbour c′ = c + e_x, e_y, e_z (k_c of them): term
// ‖N_c − N_c′‖₁ (Ln1, weight λ1; sign() is 0 at 0) and ‖N_c − N_c′‖₂² (Ln2, weight λ2), divided
// by k_c; a pair where either |n|² ≤ 1e-12 (no direction) is skipped and counted.
// loss = Σ_c Σ_pairs (λ1·L1 + λ2·L2)/k_c / M, with M = `cells` = the number of chunk cells with
// k_c ≥ 1: a mean over the cells that have neighbours. M and k_c depend on the allocation only:
// the host computes M per chunk from a prefix count and k_c once per grid
// (cpu::surface_reg::NormalPrefix).
// The chunk is the cells of the vertex rows (start + i) mod rows for i < count: the host passes
// start reduced mod rows and count clamped to rows (no integer division here), and may draw
// start anywhere.
// Gather, no atomics: every cell c evaluates its own kept forward pairs (if c is in the chunk:
// the loss, the skipped pairs, and g = w_c·(λ1·sign(d) + 2λ2·d), d = N_c − N_c′, w_c =
// 1/(k_c·M)) and, again, its kept backward pairs (c − e_a, c) with c − e_a in the chunk (−g of
// that pair, with w_{c−e_a}); G = Σ own g (x, y, z) + Σ backward −g (x, y, z), in that order, and
// ∂L/∂n_c = (G − N·(N·G))/|n_c|.
// The cell's corners then get ∂L/∂δ_b = corner_grad(b, ∂L/∂n_c) = Σ_a (∂L/∂n_c)_a·(bit_a(b) ?
// +¼ : −¼) (∂n/∂δ_b contracted), gathered per vertex by surface_normal_reg_gather.
// Thread mapping: flat id = i < work, one existing cell of the chunk's window each (as the cells
// pass: row r = cell_rows[range_row(first, i, n_cells)]); one owner per written element. Every
// cell in a pair with a chunk cell is in the window; the other cells' corners are left as they
// were (the gather reads only the window's). The cells that do not exist are in no pair and keep
// corners = +∞ from the buffer's creation.
// Inputs: cell_rows, n_cells, first, work, nbr (rows of the face neighbours), normals (pass 1;
// an entry outside the window is read only for a backward neighbour outside the chunk, and that
// pair is dropped), rows, start (< rows), count (≤ rows), cells, lambda1, lambda2.
// Outputs: corners[8·r + b] = corner_grad(b, ∂L/∂n_c) for a cell in a kept pair, else +∞
// (plain stores, as 4 words); loss[0] += loss and skipped[0] += skipped pairs (atomic adds, one
// per subgroup; the host zeroes both).
// CPU twin: `cpu::surface_normal_reg_pairs::normal_pairs`.
#include "common.glsl"
#include "normal_reg.glsl"
#extension GL_EXT_shader_atomic_float : require
#extension GL_EXT_control_flow_attributes : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#extension GL_KHR_shader_subgroup_basic : require
layout(local_size_x = 64) in;

layout(push_constant, scalar) uniform Push {
    U32Buf cell_rows;
    U64Buf nbr;
    Vec4Buf normals;
    U64Buf corners;
    F32Buf loss;
    U32Buf skipped;
    uint n_cells;
    uint first;
    uint work;
    uint rows;
    uint start;
    uint count;
    uint cells;
    float lambda1;
    float lambda2;
} pc;

float norm3(vec3 n) {
    precise float r = sqrt((n.x * n.x + n.y * n.y) + n.z * n.z);
    return r;
}

float sign0(float x) {
    return x > 0.0 ? 1.0 : (x < 0.0 ? -1.0 : 0.0);
}

// Whether row r is in the chunk (start < rows, count ≤ rows).
bool in_chunk(uint r) {
    return range_contains(pc.start, pc.count, pc.rows, r);
}

// ∂n/∂δ_b contracted with gn: Σ_a gn_a·(bit_a(b) ? +¼ : −¼).
float corner_grad(uint b, vec3 gn) {
    vec3 q = gn * 0.25;
    precise float g = ((((b >> 2u) & 1u) != 0u ? q.x : -q.x) + (((b >> 1u) & 1u) != 0u ? q.y : -q.y))
        + ((b & 1u) != 0u ? q.z : -q.z);
    return g;
}

// The gradient g with respect to N_a of the pair term of (a, b) with weight w, d = N_a − N_b.
vec3 pair_grad(float w, vec3 d) {
    precise vec3 g = w * (pc.lambda1 * vec3(sign0(d.x), sign0(d.y), sign0(d.z)) + (2.0 * pc.lambda2) * d);
    return g;
}

// The work of cell (row) r: writes its corners, returns its loss share; skipped = its forward
// pairs dropped for a tiny normal.
float cell_term(uint r, out uint skipped) {
    skipped = 0u;
    vec4 own = unpack4(pc.normals.v[r]);
    uint st = cell_status(own);
    precise vec3 g = vec3(0.0);
    bool member = false;
    float cell_loss = 0.0;
    vec3 n_c = own.xyz / norm3(own.xyz);
    if (st != 0u && in_chunk(r)) {
        // The rows of the forward face neighbours along x, y, z: corners of the cell, which
        // exists, so they are allocated.
        ivec2 kz = nbr_word(r, 0u);
        ivec2 yx = nbr_word(r, 1u);
        uint fwd[3] = uint[3](uint(yx.y), uint(yx.x), uint(kz.y));
        vec3 nn[3];
        bool ok[3];
        uint k = cell_k(own);
        [[unroll]] for (uint a = 0u; a < 3u; a++) {
            vec4 nb = unpack4(pc.normals.v[fwd[a]]);
            uint sn = cell_status(nb);
            nn[a] = nb.xyz;
            ok[a] = sn == 2u && st == 2u;
            if (sn != 0u && !ok[a]) skipped++;
        }
        if (ok[0] || ok[1] || ok[2]) {
            float w = 1.0 / (float(k) * float(pc.cells));
            precise float lsum = 0.0;
            [[unroll]] for (uint a = 0u; a < 3u; a++) {
                if (!ok[a]) continue;
                vec3 n_n = nn[a] / norm3(nn[a]);
                precise vec3 d = n_c - n_n;
                precise float l1 = (abs(d.x) + abs(d.y)) + abs(d.z);
                precise float l2 = (d.x * d.x + d.y * d.y) + d.z * d.z;
                lsum += pc.lambda1 * l1 + pc.lambda2 * l2;
                g += pair_grad(w, d);
            }
            member = true;
            precise float lw = w * lsum;
            cell_loss = lw;
        }
    }
    if (st == 2u) {
        // The rows of the backward face neighbours along x, y, z (−1: none).
        ivec2 z = nbr_word(r, 4u);
        ivec2 yx = nbr_word(r, 5u);
        int bwd[3] = int[3](yx.y, yx.x, z.y);
        [[unroll]] for (uint a = 0u; a < 3u; a++) {
            if (bwd[a] < 0) continue;
            uint rb = uint(bwd[a]);
            vec4 nb = unpack4(pc.normals.v[rb]);
            if (cell_status(nb) != 2u || !in_chunk(rb)) continue;
            float w = 1.0 / (float(cell_k(nb)) * float(pc.cells));
            precise vec3 d = nb.xyz / norm3(nb.xyz) - n_c;
            g -= pair_grad(w, d);
            member = true;
        }
    }
    float c[8];
    [[unroll]] for (uint b = 0u; b < 8u; b++) c[b] = uintBitsToFloat(NO_PAIR_BITS);
    if (member) {
        float rc = norm3(own.xyz);
        precise float p = (n_c.x * g.x + n_c.y * g.y) + n_c.z * g.z;
        precise vec3 u = (g - n_c * p) / rc;
        [[unroll]] for (uint b = 0u; b < 8u; b++) c[b] = corner_grad(b, u);
    }
    [[unroll]] for (uint w = 0u; w < 4u; w++) {
        pc.corners.v[4u * r + w] = packUint2x32(uvec2(floatBitsToUint(c[2u * w]), floatBitsToUint(c[2u * w + 1u])));
    }
    return cell_loss;
}

void main() {
    uint i = flat_id();
    uint skipped = 0u;
    float l = i < pc.work ? cell_term(pc.cell_rows.v[range_row(pc.first, i, pc.n_cells)], skipped) : 0.0;
    uint sk = subgroupAdd(skipped);
    float sl = subgroupAdd(l);
    if (subgroupElect()) {
        if (sk != 0u) atomicAdd(pc.skipped.v[0], sk);
        if (sl != 0.0) atomicAdd(pc.loss.v[0], sl);
    }
}
