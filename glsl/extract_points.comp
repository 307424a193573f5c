#version 460
// extract_points — level-set point extraction with dense virtual rays (method.md §4).
// Thread mapping: one invocation per (cell, axis): i = 3 * cell + axis over the list `cells` of
// cells whose 8 corners are allocated. For each level τ with min ≤ τ ≤ max over the corners and
// each of the R² rays of that axis (origins o′ on the cell's entry face x_axis = 0, the other two
// coordinates on the lattice j / (R − 1), j = 0..R−1, or 0.5 when R = 1; direction +axis; L = 1):
// solve the cell cubic of `field` − τ on [0, 1) and keep the FIRST crossing, rising or falling
// (back faces are not culled), whose trilerped `opacity` ≥ `min_opacity` (no test when
// `opacity` is the null address). Emits the point through an atomic counter: slot
// atomicAdd(counter[0], 1) is written when < capacity; counter[0] ends as the number of points
// found, so the host can retry with a larger buffer.
// Inputs: cells (links slot of corner 000), links (X·Y·Z, < 0 empty), field and opacity (per
// allocated vertex), levels[n_levels]. Output: points, counter.
// CPU twin: `cpu::extract_points::extract_points`.
#include "common.glsl"
#include "cubic.glsl"
#include "trilerp.glsl"
#include "extract.glsl"
layout(local_size_x = 64) in;

layout(push_constant, scalar) uniform Push {
    U32Buf cells;
    I32Buf links;
    F32Buf field;
    F32Buf opacity;
    F32Buf levels;
    U32Buf counter;
    ExtractPointBuf points;
    uint capacity;
    uint n_cells;
    uint n_levels;
    uint res_y;
    uint res_z;
    uint rays_per_axis;
    float min_opacity;
} pc;

float lattice(uint j, uint r) {
    return r <= 1u ? 0.5 : float(j) / float(r - 1u);
}

void main() {
    uint i = flat_id();
    if (i >= 3u * pc.n_cells) return;
    uint cell = pc.cells.v[i / 3u];
    uint axis = i % 3u;
    bool has_opacity = uint64_t(pc.opacity) != 0ul;
    uint yz = pc.res_y * pc.res_z;
    float c[8];
    float a[8];
    float cmin = 3.4028235e38;
    float cmax = -3.4028235e38;
    [[unroll]] for (uint k = 0u; k < 8u; ++k) {
        uint slot = cell + (k >> 2) * yz + ((k >> 1) & 1u) * pc.res_z + (k & 1u);
        int row = pc.links.v[slot];
        c[k] = pc.field.v[row];
        a[k] = 0.0;
        if (has_opacity) a[k] = pc.opacity.v[row];
        cmin = min(cmin, c[k]);
        cmax = max(cmax, c[k]);
    }
    vec3 d = vec3(axis == 0u ? 1.0 : 0.0, axis == 1u ? 1.0 : 0.0, axis == 2u ? 1.0 : 0.0);
    uint R = pc.rays_per_axis;
    for (uint l = 0u; l < pc.n_levels; ++l) {
        float tau = pc.levels.v[l];
        if (!(cmin <= tau && tau <= cmax)) continue;
        for (uint ju = 0u; ju < R; ++ju) {
            for (uint jv = 0u; jv < R; ++jv) {
                float u = lattice(ju, R);
                float v = lattice(jv, R);
                vec3 o = axis == 0u ? vec3(0.0, u, v) : (axis == 1u ? vec3(v, 0.0, u) : vec3(u, v, 0.0));
                CubicCrossings x = cubic_solve(cubic_cell(c, o, d), cubic_level_ends(c, o, d, 1.0, tau), 1.0, 0.0);
                for (uint k = 0u; k < x.n; ++k) {
                    float s = k == 0u ? x.s.x : (k == 1u ? x.s.y : x.s.z);
                    precise vec3 p = fma(vec3(s), d, o);
                    float alpha = 1.0;
                    if (has_opacity) {
                        float sa = trilerp(a, p);
                        if (!(sa >= pc.min_opacity)) continue;
                        alpha = 1.0 - exp(-max(sa, 0.0));
                    }
                    uint slot = atomicAdd(pc.counter.v[0], 1u);
                    if (slot < pc.capacity) {
                        ExtractPoint e;
                        e.local = p;
                        e.grad = trilerp_grad(c, p).yzw;
                        e.alpha = alpha;
                        e.cell = cell;
                        e.level = l;
                        e.ray = axis * R * R + ju * R + jv;
                        pc.points.v[slot] = e;
                    }
                    break;
                }
            }
        }
    }
}
