#version 460
// dda_walk — walks each ray through the cells of an n³-vertex grid (glsl/lib/dda.glsl).
// Thread mapping: one invocation per ray (flat 1-D index over a 2-D grid).
// Inputs: `rays` (6 floats per ray: o.xyz, d.xyz in grid units), `n_rays`, grid size `n`,
// `t_min`, and `k`, the number of leading cells to record per ray (0: count and checksum only,
// which is the benchmark mode).
// Outputs: `stats[2i] = number of cells visited`, `stats[2i+1]` = checksum of the whole walk
// (dda_hash over dda_cell_index); for j < min(count, k): `cells[k·i + j]` = cell index,
// `ts[2(k·i + j)]`, `ts[2(k·i + j) + 1]` = entry and exit t. CPU twin: `cpu::dda_walk`.
#include "common.glsl"
#include "dda.glsl"
layout(local_size_x = 64) in;

layout(push_constant, scalar) uniform Push {
    F32Buf rays;
    U32Buf stats;
    U32Buf cells;
    F32Buf ts;
    uint n_rays;
    uint n;
    uint k;
    float t_min;
} pc;

void main() {
    uint i = flat_id();
    if (i >= pc.n_rays) return;
    vec3 o = vec3(pc.rays.v[6 * i], pc.rays.v[6 * i + 1], pc.rays.v[6 * i + 2]);
    vec3 d = vec3(pc.rays.v[6 * i + 3], pc.rays.v[6 * i + 4], pc.rays.v[6 * i + 5]);
    Dda s = dda_init(o, d, int(pc.n), pc.t_min);
    uint count = 0u;
    uint h = DDA_HASH0;
    ivec3 c;
    float t0, t1;
    while (dda_next(s, c, t0, t1)) {
        uint idx = dda_cell_index(c, pc.n);
        h = dda_hash(h, idx);
        if (count < pc.k) {
            uint j = pc.k * i + count;
            pc.cells.v[j] = idx;
            pc.ts.v[2 * j] = t0;
            pc.ts.v[2 * j + 1] = t1;
        }
        count++;
    }
    pc.stats.v[2 * i] = count;
    pc.stats.v[2 * i + 1] = h;
}
