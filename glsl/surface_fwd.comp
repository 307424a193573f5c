#version 460
// surface_fwd — stage-2 (αSurf) forward rendering of a batch of rays (method.md §3.2).
// Thread mapping: one invocation per ray.
// Per ray: grid = p·scale + offset (direction normalised in grid space, so s is in voxels); the
// cell walk of glsl/lib/surface_walk.glsl (shared with surface_train): DDA over the cells of
// [0, n−1]³ front to back from t = 0; a cell with an unallocated corner is skipped; cubic
// coefficients once per cell; per level τ_i that passes min/max, then segment
// culling (surf_segment_mask) the crossings of δ − τ_i on [0, L); only rising (front-face) crossings are hits, sorted by s within the cell; at
// hit j: α = 1 − exp(−max(σα, 0)), colour max(0, SH + 0.5) (trilerped at the hit, basis on the unit
// scene direction), α̃ = α·γ_a(k); C = Σ w_j c_j + T·B (B: bg behind the ray), k the truncation count: j, or with
// truncation_count ≠ SURF_COUNT_RAY the hits since the ray last entered level 0 (surf_restart). A
// hit with k ≥ its limit (a, or 1 behind the first structure with SURF_COUNT_THROUGH: γ = 0, not
// shaded, counted as cut) ends the ray, or is passed over when counting per structure; the ray
// also stops once T < stop_thresh.
// Skipping (block_skip ≠ 0) with the skip structure `blocks` (glsl/lib/surface_blocks.glsl): the
// walk covers only the ray's span inside the allocated box (surf_box_span); a cell whose
// 2^block_shift-cell block has level mask 0 (kernel surface_blocks) is not read and the walk
// restarts at the exit of the cube of empty blocks around it (its radius: kernel
// surface_block_radius; surf_block_skip: the same pieces as the continuous walk, so the same
// hits); a cell whose live bit is clear (kernel surface_live_cells) is passed over unread.
// Inputs: links (n³ i32, < 0 unallocated), per allocated vertex delta, opacity (raw σα) and sh
// (27), params (SurfParams: scale, offset, a, stop_thresh, n_rays, levels[n_levels ≤ 8]; the loss
// weights unused), bg (Background: its colour behind its spheres, background.glsl), rays (6 floats: scene origin, direction), blocks
// (live-cell words, nb³ u32 level masks, the allocated box; read only when block_skip ≠ 0),
// block_shift.
// Outputs: out[r] = (rgb, transmittance, hits composited); stats (SurfCounts) += cells read (live
// cells: links read), cubic solves, solves skipped by min/max or segment culling, hits composited,
// hits cut by truncation, blocks skipped (subgroup-reduced atomics).
// CPU twin: `cpu::surface_fwd::render`.
#include "common.glsl"
#include "background.glsl"
// Every hit of a cell: a is not bounded here (surface.glsl).
#define SURF_CELL_KEEP 16u
#include "surface.glsl"
#include "surface_blocks.glsl"
#extension GL_KHR_shader_subgroup_arithmetic : require
#extension GL_KHR_shader_subgroup_basic : require
layout(local_size_x = 64) in;

layout(push_constant, scalar) uniform Push {
    I32Buf links;
    F32Buf delta;
    F32Buf opacity;
    F32Buf sh;
    SurfParamsBuf params;
    F32Buf rays;
    SurfOutBuf out_rays;
    SurfCountsBuf stats;
    U32Buf blocks;
    BackgroundBuf bg;
    uint n;
    uint block_skip;
    uint block_shift;
} pc;

// The skip structure the cell walk reads.
#define SURF_WALK_BLOCKS pc.blocks
#include "surface_walk.glsl"

void main() {
    uint r = flat_id();
    SurfParams prm = pc.params.v[0];
    if (r >= prm.n_rays) return;
    vec3 ro = vec3(pc.rays.v[6u * r], pc.rays.v[6u * r + 1u], pc.rays.v[6u * r + 2u]);
    vec3 rd = vec3(pc.rays.v[6u * r + 3u], pc.rays.v[6u * r + 4u], pc.rays.v[6u * r + 5u]);
    float a = prm.a;
    float stop_thresh = prm.stop_thresh;
    uint nl = min(prm.n_levels, SURF_MAX_LEVELS);
    float lv[SURF_MAX_LEVELS];
    for (uint i = 0u; i < SURF_MAX_LEVELS; i++) lv[i] = i < nl ? prm.levels[i] : 0.0;
    vec3 og, dn;
    surf_ray(ro, rd, prm.scale, prm.offset, og, dn);
    float y[9];
    sh_basis(ray_unit(rd), y);
    vec3 color = vec3(0.0);
    float T = 1.0;
    uint j = 0u;
    // The truncation count: j itself, or with counting per structure the hits since the ray last
    // entered level 0 (surf_restart), truncated from k ≥ limit.
    uint k = 0u;
    float limit = a;
    uint structures = 0u;
    bool per_structure = prm.truncation_count != SURF_COUNT_RAY;
    SurfCounts cnt = SURF_COUNTS_ZERO;
    SkipRef blocks = SkipRef(pc.block_skip != 0u, pc.block_shift);
    CellWalk walk = cell_walk_new(og, dn, lv, nl, blocks);
    WalkCell cell;
    // Per level, the sign of δ − τ just before the last solved cell's exit (bits of face_pos /
    // face_neg) and that exit's t (FaceSigns in the twin).
    float face_t = 0.0;
    uint face_pos = 0u;
    uint face_neg = 0u;
    bool done = false;
    while (!done && cell_walk_next(walk, cell)) {
        float t0 = cell.piece.t0;
        float t1 = cell.piece.t1;
        precise float L = t1 - t0;
        float hs[SURF_CELL_KEEP];
        // Signs before the entry point: the last solved cell's, when it ended here.
        bool joined = t0 == face_t;
        uint epos, eneg;
        vec2 outer;
        uint nh = surf_cell_hits(cell.c, cell.cc, cell.q0, cell.q1, L, lv, cell.mask,
                                 joined ? face_pos : 0u, joined ? face_neg : 0u, hs, epos, eneg,
                                 outer);
        face_t = t1;
        face_pos = epos;
        face_neg = eneg;
        for (uint h = 0u; h < nh; h++) {
            float s_hit = surf_pop(hs);
            surf_restart(prm.truncation_count, a, s_hit, outer, k, limit, structures);
            // A truncated hit (γ = 0) ends the ray, or with counting per structure is passed
            // over (a later structure restarts the count).
            if (float(k) >= limit) {
                cnt.cut++;
                if (per_structure && T >= SURF_PASS_MIN_T) continue;
                done = true;
                break;
            }
            precise vec3 p = clamp(cell.q0 + s_hit * dn, 0.0, 1.0);
            float wt[8];
            trilerp_weights(p, wt);
            precise float sa = 0.0;
            for (int i = 0; i < 8; i++) sa += wt[i] * pc.opacity.v[cell.lk[i]];
            float alpha = surf_alpha(sa);
            precise float at = alpha * surf_gamma(a, k);
            float sh[27];
            for (int k = 0; k < 27; k++) sh[k] = 0.0;
            [[unroll]] for (int i = 0; i < 8; i++) {
                float shv[27];
                SH27_LOAD(pc.sh, uint(cell.lk[i]), shv);
                [[unroll]] for (int k = 0; k < 27; k++) {
                    precise float acc = sh[k] + wt[i] * shv[k];
                    sh[k] = acc;
                }
            }
            vec3 col;
            for (int ch = 0; ch < 3; ch++) {
                precise float acc = 0.5;
                for (int k = 0; k < 9; k++) {
                    precise float a2 = acc + y[k] * sh[ch * 9 + k];
                    acc = a2;
                }
                col[ch] = max(acc, 0.0);
            }
            precise float wj = T * at;
            precise vec3 acc = color + wj * col;
            color = acc;
            precise float tn = T * (1.0 - at);
            T = tn;
            j++;
            k++;
            cnt.hits++;
            if (T < stop_thresh) {
                done = true;
                break;
            }
        }
    }
    cnt.cells = walk.counts.cells;
    cnt.solves = walk.counts.solves;
    cnt.culled = walk.counts.culled;
    cnt.blocks_skipped = walk.counts.blocks_skipped;
    SurfOut o;
    float t_bg;
    precise vec3 outc = color + T * background_behind(pc.bg.v[0], ro, rd, t_bg);
    o.rgb = outc;
    o.transmittance = T;
    o.hits = j;
    pc.out_rays.v[r] = o;
    SURF_COUNTS_SUBGROUP_ADD(pc.stats.v[0], cnt);
}
