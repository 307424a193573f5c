#version 460
// surface_normal_reg — gradient and value of the stage-2 normal regularisers Ln1 and Ln2, fused
// (method.md §3.4). A cell is named by its lower corner vertex (allocated: row r, slot
// row_slot[r]); it EXISTS when it lies inside the grid and its 8 corners are allocated. Its
// normal is n = (Σ_{b,c} δ_1bc − Σ_{b,c} δ_0bc, likewise for y and z)/4 (corner k = 4·x + 2·y + z
// bit) and N = n/|n|. For each existing cell c of the chunk and each existing forward neighbour
// c′ = c + e_x, e_y, e_z (k_c of them): term ‖N_c − N_c′‖₁ (Ln1, weight λ1; sign() is 0 at 0)
// and ‖N_c − N_c′‖₂² (Ln2, weight λ2), divided by k_c; a pair where either |n|² ≤ 1e-12 (no
// direction) is skipped and counted. loss = Σ_c Σ_pairs (λ1·L1 + λ2·L2)/k_c / M, with M = `cells`
// = the number of chunk cells with k_c ≥ 1: a mean over the cells that have neighbours. M and
// k_c depend on the allocation only, so the host computes M per chunk from a prefix count made
// once per grid (cpu::surface_reg::NormalPrefix) and a single pass suffices.
// The chunk is the cells of the vertex rows (start + i) mod rows for i < min(count, rows): this
// kernel wraps, so the caller may draw start anywhere in [0, rows). Rows, not slots: at 128³
// about 5 % of the slots are allocated, and an invocation per slot cost more than all the
// cells' work on lavapipe (measured); with rows in slot order (as SurfaceGrid::from_density
// allocates them) a row chunk is a contiguous run of cell slots.
// Thread mapping: flat id = i, one cell (row) each.
// Inputs: links, row_slot (slot of each allocated row), delta, res, rows, start, count, cells,
// lambda1, lambda2.
// Outputs: grad += ∂loss/∂δ by float atomic adds (per cell with a kept pair: 8 for its corners,
// 4 more per kept neighbour), those corners given the touched bits touch_bits (step.glsl); loss[0] += loss and
// skipped[0] += skipped pairs (atomic adds, one per subgroup; the host zeroes both).
// CPU twin: cpu::surface_reg::surface_normal_reg.
#include "common.glsl"
#extension GL_EXT_shader_atomic_float : require
#extension GL_EXT_control_flow_attributes : require
layout(local_size_x = 64) in;

layout(push_constant, scalar) uniform Push {
    I32Buf links;
    U32Buf row_slot;
    F32Buf delta;
    F32Buf grad;
    U32Buf step;
    F32Buf loss;
    U32Buf skipped;
    uvec3 res;
    uint rows;
    uint start;
    uint count;
    uint cells;
    float lambda1;
    float lambda2;
    uint touch_bits;
} pc;

#include "step.glsl"

const float TINY_NORMAL2 = 1e-12;

uint axis_stride(uint a) {
    return a == 0u ? pc.res.y * pc.res.z : (a == 1u ? pc.res.z : 1u);
}

uvec3 slot_vertex(uint s) {
    return uvec3(s / (pc.res.y * pc.res.z), (s / pc.res.z) % pc.res.y, s % pc.res.z);
}

// Cell with lower corner slot s at vertex v: 0 = outside the grid or a corner unallocated,
// 1 = tiny normal, 2 = a direction. Fills the corner links l and the normal n.
uint cell_normal(uint s, uvec3 v, out int l[8], out vec3 n) {
    n = vec3(0.0);
    [[unroll]] for (uint k = 0u; k < 8u; k++) l[k] = -1;
    if (any(greaterThanEqual(v + 1u, pc.res))) return 0u;
    float d[8];
    [[unroll]] for (uint k = 0u; k < 8u; k++) {
        uint cs = s + ((k >> 2u) & 1u) * axis_stride(0u) + ((k >> 1u) & 1u) * pc.res.z + (k & 1u);
        l[k] = pc.links.v[cs];
        if (l[k] < 0) return 0u;
        d[k] = pc.delta.v[l[k]];
    }
    precise float mx = ((d[4] + d[5]) + (d[6] + d[7])) - ((d[0] + d[1]) + (d[2] + d[3]));
    precise float my = ((d[2] + d[3]) + (d[6] + d[7])) - ((d[0] + d[1]) + (d[4] + d[5]));
    precise float mz = ((d[1] + d[3]) + (d[5] + d[7])) - ((d[0] + d[2]) + (d[4] + d[6]));
    n = vec3(mx, my, mz) * 0.25;
    precise float n2 = (n.x * n.x + n.y * n.y) + n.z * n.z;
    return n2 <= TINY_NORMAL2 ? 1u : 2u;
}

float norm3(vec3 n) {
    precise float r = sqrt((n.x * n.x + n.y * n.y) + n.z * n.z);
    return r;
}

// ∂L/∂n from ∂L/∂N for N = n/|n|: (g − N·(N·g))/|n|.
vec3 unnormalise_grad(vec3 n, vec3 g) {
    float r = norm3(n);
    precise vec3 nn = n / r;
    precise float p = (nn.x * g.x + nn.y * g.y) + nn.z * g.z;
    precise vec3 out_g = (g - nn * p) / r;
    return out_g;
}

// ∂n/∂δ_k contracted with gn: Σ_a gn_a·(bit_a(k) ? +¼ : −¼).
float corner_grad(uint k, vec3 gn) {
    vec3 q = gn * 0.25;
    precise float g = ((((k >> 2u) & 1u) != 0u ? q.x : -q.x) + (((k >> 1u) & 1u) != 0u ? q.y : -q.y))
        + ((k & 1u) != 0u ? q.z : -q.z);
    return g;
}

float sign0(float x) {
    return x > 0.0 ? 1.0 : (x < 0.0 ? -1.0 : 0.0);
}

// The work of chunk cell id: adds its gradients, returns its loss share; skipped = its pairs
// dropped for a tiny normal.
float cell_term(uint id, out uint skipped) {
    skipped = 0u;
    if (id >= min(pc.count, pc.rows)) return 0.0;
    uint s = pc.row_slot.v[(pc.start % pc.rows + id) % pc.rows];
    uvec3 v = slot_vertex(s);
    int lc[8];
    vec3 nc;
    uint st = cell_normal(s, v, lc, nc);
    if (st == 0u) return 0.0;
    int ln[3][8];
    vec3 nn[3];
    bool ok[3];
    uint k = 0u;
    [[unroll]] for (uint a = 0u; a < 3u; a++) {
        uvec3 va = v;
        va[a] += 1u;
        uint sn = cell_normal(s + axis_stride(a), va, ln[a], nn[a]);
        if (sn != 0u) k++;
        ok[a] = sn == 2u && st == 2u;
        if (sn != 0u && !ok[a]) skipped++;
    }
    if (!(ok[0] || ok[1] || ok[2])) return 0.0;
    float w = 1.0 / (float(k) * float(pc.cells));
    float rc = norm3(nc);
    vec3 n_c = nc / rc;
    precise vec3 gc = vec3(0.0);
    float g[8];
    [[unroll]] for (uint kk = 0u; kk < 8u; kk++) g[kk] = 0.0;
    precise float lsum = 0.0;
    [[unroll]] for (uint a = 0u; a < 3u; a++) {
        if (!ok[a]) continue;
        float r = norm3(nn[a]);
        vec3 n_n = nn[a] / r;
        precise vec3 d = n_c - n_n;
        precise float l1 = (abs(d.x) + abs(d.y)) + abs(d.z);
        precise float l2 = (d.x * d.x + d.y * d.y) + d.z * d.z;
        lsum += pc.lambda1 * l1 + pc.lambda2 * l2;
        precise vec3 gn = w * (pc.lambda1 * vec3(sign0(d.x), sign0(d.y), sign0(d.z))
            + (2.0 * pc.lambda2) * d);
        gc += gn;
        vec3 gnn = unnormalise_grad(nn[a], -gn);
        uint bit = 4u >> a;
        [[unroll]] for (uint kk = 0u; kk < 8u; kk++) {
            float gk = corner_grad(kk, gnn);
            if ((kk & bit) == 0u) {
                g[kk | bit] += gk;
            } else {
                atomicAdd(pc.grad.v[uint(ln[a][kk])], gk);
                touch_mask(uint(ln[a][kk]), pc.touch_bits);
            }
        }
    }
    vec3 gnc = unnormalise_grad(nc, gc);
    [[unroll]] for (uint kk = 0u; kk < 8u; kk++) {
        precise float gk = g[kk] + corner_grad(kk, gnc);
        atomicAdd(pc.grad.v[uint(lc[kk])], gk);
        touch_mask(uint(lc[kk]), pc.touch_bits);
    }
    precise float cell_loss = w * lsum;
    return cell_loss;
}

void main() {
    uint skipped;
    float l = cell_term(flat_id(), skipped);
    uint sk = subgroupAdd(skipped);
    float sl = subgroupAdd(l);
    if (subgroupElect()) {
        if (sk != 0u) atomicAdd(pc.skipped.v[0], sk);
        if (sl != 0.0) atomicAdd(pc.loss.v[0], sl);
    }
}
