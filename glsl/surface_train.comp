#version 460
// surface_train — one stage-2 (αSurf) training pass over a batch of rays, forward and backward
// fused per ray (method.md §3.2–3.4): squared error, entropy LH and depth consistency Lc.
// Thread mapping: one invocation per ray.
// Forward: the cell walk of glsl/lib/surface_walk.glsl (shared with surface_fwd: same DDA,
// skipping, culling) with surface_fwd's per-cell hits, truncation and early stop,
// recording the ≤ a ≤ SURF_MAX_HITS composited hits in registers together with what the
// backward needs of them (hit point, depth, σα, α̃, raw colour, and the derivatives along the ray
// of σα, raw colour and δ: dσα/ds, draw/ds, f′(s), plus the f′ guard verdict).
// Backward: compositing recomputed from the records; losses; ∂LH/∂w_j and ∂Lc/∂t_j; a reverse
// recurrence (colour and entropy seen from behind each hit) gives ∂L/∂α̃_j and ∂L/∂raw_j; then
// ∂L/∂σα = ∂L/∂α̃·γ·e^{−σα} (σα > 0), ∂L/∂SH = ∂L/∂raw·Y (ReLU-gated), and δ through the hit
// position: ∂L/∂δ_i = −w_i·(∂L/∂s)/f′(s), no δ gradient where |f′| ≤ FPRIME_GUARD·(max − min of
// the cell's δ) (counted). Per-corner gradients of consecutive hits in the same cell are summed
// in registers (in the reverse order) and flushed with one float atomic per corner and parameter
// that received a non-zero term when the cell changes (SH: 3 accumulators per corner, times Y_k at
// the flush);
// every vertex that receives a gradient is touched in all three groups (step.glsl).
// Inputs: links (n³, < 0 unallocated), skip: the skip structure (glsl/lib/surface_blocks.glsl):
// words [0, W = ⌈n³/32⌉) the live-cell bits of surface_live_cells (a cell with its bit clear has
// an unallocated corner or no level within its δ range: one bit read instead of 8 links and 8 δ),
// words [W, W + nb³) the 2^block_shift-cell block level masks of surface_blocks with the empty
// radii of surface_block_radius (a cell in a mask-0 block cannot hold a hit: the walk restarts
// past the cube of empty blocks around it, surf_block_skip), both built
// for the current δ or with a margin bounding its drift since (exact), then the allocated box
// (static: the walk covers only the ray's span inside it, surf_box_span); block_shift; delta,
// opacity (raw σα), sh (27) per allocated vertex;
// params (SurfParams: scale, offset, a, stop_thresh, the loss weights grad_scale, lambda_h,
// lambda_c, n_rays, the levels; n_levels used; the address of the per-ray importance weights ω
// of a focused batch, gpu::TrainViewBuffers, 0: ω = 1: the ray's loss terms are ω times the
// unweighted ones, its gradients and the RayLoss it reports alike); rays (6 floats), targets
// (3 floats); bg (the background composited behind the last hit: C = Σ w_j c_j + T·B, B the
// colour behind the spheres, background.glsl; stage 2 does not train the spheres).
// Outputs: grad_delta, grad_opacity, grad_sh += (float atomics), touched list (step buffer);
// when bg.learn ≠ 0, bg.grad += Σ_rays dL/dC·T·T_L (subgroup-reduced float atomics);
// out_rays[r] = RayLoss (squared error, entropy, consistency, hits composited); stats
// (TrainCounts) += cells read (live cells: links and δ loaded), cubic solves, solves culled
// (min/max or segment), hits composited, hits cut by truncation, guarded hits, gradient atomic
// adds, blocks skipped (subgroup-reduced).
// CPU twin: `cpu::surface_train::train`. The pieces that read no buffer are in
// glsl/lib/surface_train.glsl (twin: src/math/surface_train.rs).
#extension GL_EXT_shader_atomic_float : require
#include "common.glsl"
// A cell's hit list keeps SURF_MAX_HITS (surface.glsl; the hits a ray records, a ≤ this), all a
// ray can composite.
#define SURF_CELL_KEEP SURF_MAX_HITS
#include "surface.glsl"
#include "surface_blocks.glsl"
#include "background.glsl"
layout(local_size_x = 64) in;

layout(push_constant, scalar) uniform Push {
    I32Buf links;
    U32Buf skip;
    F32Buf delta;
    F32Buf opacity;
    F32Buf sh;
    SurfParamsBuf params;
    F32Buf rays;
    F32Buf targets;
    F32Buf grad_delta;
    F32Buf grad_opacity;
    F32Buf grad_sh;
    RayLossBuf out_rays;
    TrainCountsBuf stats;
    StepRecord step;
    BackgroundBuf bg;
    uint n;
    uint block_shift;
} pc;

// The skip structure the cell walk reads.
#define SURF_WALK_BLOCKS pc.skip
#include "surface_walk.glsl"

#include "step.glsl"
#include "surface_train.glsl"

// Adds a cell's per-corner gradient sums (one atomic per corner and parameter that received a
// non-zero term, read from the masks of CornerSums), touches the corners that get one, clears the
// sums and masks; returns the atomic adds.
uint flush(ivec3 cell, float y[9], inout CornerSums s) {
    if (cell.x < 0) return 0u;
    int lk[8];
    cell_links(pc.links, uvec3(pc.n), cell, lk);
    uint adds = 0u;
    for (uint i = 0u; i < 8u; i++) {
        float gd = s.d[i];
        float ga = s.a[i];
        vec3 gc = s.c[i];
        s.d[i] = 0.0;
        s.a[i] = 0.0;
        s.c[i] = vec3(0.0);
        bool bd = ((s.nz_d >> i) & 1u) != 0u;
        bool ba = ((s.nz_a >> i) & 1u) != 0u;
        uint bc = (s.nz_c >> (3u * i)) & 7u;
        if (!bd && !ba && bc == 0u) continue;
        uint row = uint(lk[i]);
        touch_mask(row, TOUCH_SURFACE);
        if (bd) {
            atomicAdd(pc.grad_delta.v[row], gd);
            adds++;
        }
        if (ba) {
            atomicAdd(pc.grad_opacity.v[row], ga);
            adds++;
        }
        for (uint ch = 0u; ch < 3u; ch++) {
            if (((bc >> ch) & 1u) == 0u) continue;
            uint base = row * 27u + ch * 9u;
            for (uint k = 0u; k < 9u; k++) {
                precise float g = gc[ch] * y[k];
                atomicAdd(pc.grad_sh.v[base + k], g);
            }
            adds += 9u;
        }
    }
    s.nz_d = 0u;
    s.nz_a = 0u;
    s.nz_c = 0u;
    return adds;
}

// The record of the hit at s_hit along the piece of `cell` (truncation parameter a, count k; sid
// left 0 for the caller): σα, α̃, the shading and the derivatives along the ray dn the backward
// pass needs (SH basis y), and the f′ guard verdict.
HitRec hit_record(WalkCell cell, float s_hit, vec3 dn, float y[9], float a, uint k) {
    HitRec hr;
    precise vec3 p = clamp(cell.q0 + s_hit * dn, 0.0, 1.0);
    float wt[8];
    trilerp_weights(p, wt);
    float dw[8];
    trilerp_dwds(p, dn, dw);
    precise float sa = 0.0;
    [[unroll]] for (int i = 0; i < 8; i++) sa += wt[i] * pc.opacity.v[cell.lk[i]];
    float gam = surf_gamma(a, k);
    precise float at = surf_alpha(sa) * gam;
    hr.cell = cell.piece.cell;
    hr.p = p;
    precise float depth = cell.piece.t0 + s_hit;
    hr.depth = depth;
    hr.sa = sa;
    hr.at = at;
    hr.gam = gam;
    hr.sid = 0u;
    hr.raw = vec3(0.5);
    hr.draw = vec3(0.0);
    hr.dsa = 0.0;
    hr.f1 = 0.0;
    [[unroll]] for (int i = 0; i < 8; i++) {
        uint row = uint(cell.lk[i]);
        float shv[27];
        SH27_LOAD(pc.sh, row, shv);
        surf_shade_corner(hr, wt[i], dw[i], pc.opacity.v[row], cell.c[i], y, shv);
    }
    hr.guard = surf_guard(hr.f1, cell.c);
    return hr;
}

// The forward walk of the ray (og, dn) through levels lv (nl used), recording the composited hits
// in rec (registers: set_hit); returns their number. The same stopping rules as surface_fwd.
uint walk_hits(vec3 og, vec3 dn, float lv[SURF_MAX_LEVELS], uint nl, SurfParams prm, float y[9],
               inout HitRec rec[SURF_MAX_HITS], inout TrainCounts cnt) {
    float a = prm.a;
    float T = 1.0;
    uint j = 0u;
    // The truncation count: j itself, or with counting per structure the hits since the ray last
    // entered level 0 (surf_restart), truncated from k ≥ limit.
    uint k = 0u;
    float limit = a;
    uint structures = 0u;
    uint sid = 0u;
    bool per_structure = prm.truncation_count != SURF_COUNT_RAY;
    SkipRef blocks = SkipRef(true, pc.block_shift);
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
        // A cell's list holds its SURF_CELL_KEEP first hits (more are reached only when counting
        // per structure skips truncated hits; they are dropped).
        uint nk = min(nh, SURF_CELL_KEEP);
        for (uint h = 0u; h < nk; h++) {
            precise float s_hit = surf_pop(hs);
            surf_restart(prm.truncation_count, a, s_hit, outer, k, limit, structures);
            // A truncated hit (γ = 0) ends the ray, or with counting per structure is passed
            // over (a later structure restarts the count); a full record ends it.
            if (float(k) >= limit || j >= SURF_MAX_HITS) {
                cnt.cut++;
                if (per_structure && j < SURF_MAX_HITS && T >= SURF_PASS_MIN_T) continue;
                done = true;
                break;
            }
            HitRec hr = hit_record(cell, s_hit, dn, y, a, k);
            // A restarted count (k = 0 after the first record) starts the next structure.
            if (k == 0u && j > 0u) sid++;
            hr.sid = sid;
            set_hit(rec, j, hr);
            j++;
            k++;
            cnt.hits++;
            precise float tn = T * (1.0 - hr.at);
            T = tn;
            if (T < prm.stop_thresh) {
                done = true;
                break;
            }
        }
    }
    cnt.cells = walk.counts.cells;
    cnt.solves = walk.counts.solves;
    cnt.culled = walk.counts.culled;
    cnt.blocks_skipped = walk.counts.blocks_skipped;
    return j;
}

void main() {
    uint r = flat_id();
    if (r >= pc.params.v[0].n_rays) return;
    vec3 ro = vec3(pc.rays.v[6u * r], pc.rays.v[6u * r + 1u], pc.rays.v[6u * r + 2u]);
    vec3 rd = vec3(pc.rays.v[6u * r + 3u], pc.rays.v[6u * r + 4u], pc.rays.v[6u * r + 5u]);
    vec3 target = vec3(pc.targets.v[3u * r], pc.targets.v[3u * r + 1u], pc.targets.v[3u * r + 2u]);
    SurfParams prm = pc.params.v[0];
    const uint64_t weights = packUint2x32(prm.weights);
    float omega = weights != 0ul ? F32Buf(weights).v[r] : 1.0;
    uint nl = min(prm.n_levels, SURF_MAX_LEVELS);
    float lv[SURF_MAX_LEVELS];
    for (uint i = 0u; i < SURF_MAX_LEVELS; i++) lv[i] = i < nl ? prm.levels[i] : 0.0;
    vec3 og, dn;
    surf_ray(ro, rd, prm.scale, prm.offset, og, dn);
    precise vec3 dg = rd * prm.scale;
    precise float len2 = dg.x * dg.x + dg.y * dg.y + dg.z * dg.z;
    float len = sqrt(len2);
    float inv_len = len > 0.0 ? 1.0 / len : 0.0;
    float y[9];
    sh_basis(ray_unit(rd), y);
    TrainCounts cnt = TRAIN_COUNTS_ZERO;

    HitRec rec[SURF_MAX_HITS];
    uint nh = walk_hits(og, dn, lv, nl, prm, y, rec, cnt);

    // Compositing from the records, the squared error and the regularisers' terms.
    float tr[SURF_MAX_HITS + 1u];
    float wj[SURF_MAX_HITS];
    vec3 color = surf_composite(rec, nh, tr, wj);
    float t_last = tr[SURF_MAX_HITS];
    float t_bg;
    vec3 bg = background_behind(pc.bg.v[0], ro, rd, t_bg);
    precise vec3 total = color + t_last * bg;
    precise vec3 diff = total - target;
    RayLoss o;
    precise float sq = diff.x * diff.x + diff.y * diff.y + diff.z * diff.z;
    o.sq_err = omega * sq;
    o.hits = nh;
    float grad_scale = prm.grad_scale * omega;
    precise vec3 d_c = grad_scale * diff;
    float e[SURF_MAX_HITS];
    o.entropy = omega * surf_entropy(wj, nh, prm.lambda_h * omega, e);
    float d_t[SURF_MAX_HITS];
    o.consistency = omega * surf_consistency(rec, wj, nh, prm.lambda_c * omega, inv_len, d_t);
    pc.out_rays.v[r] = o;

    // Reverse pass: colour and entropy seen from behind each hit (behind the last: the
    // background); the gradients of consecutive hits in one cell are summed per corner and
    // flushed when the cell changes.
    precise vec3 s_c = bg;
    precise float s_e = 0.0;
    ivec3 cur = ivec3(-1);
    CornerSums sums = corner_sums_zero();
    for (int jj = int(nh) - 1; jj >= 0; jj--) {
        uint ji = uint(jj);
        HitRec hk = get_hit(rec, ji);
        float trk = 1.0, wk = 0.0, ek = 0.0, dtk = 0.0;
        [[unroll]] for (uint q = 0u; q < SURF_MAX_HITS; q++) {
            if (q == ji) {
                trk = tr[q];
                wk = wj[q];
                ek = e[q];
                dtk = d_t[q];
            }
        }
        vec3 d_raw;
        float d_at = surf_reverse_step(hk, trk, wk, ek, d_c, s_c, s_e, d_raw);
        float d_sa;
        float dds = surf_hit_grads(hk, d_at, d_raw, dtk, inv_len, d_sa);
        if (hk.guard) cnt.guarded++;
        if (hk.cell != cur) {
            cnt.atomic_adds += flush(cur, y, sums);
            cur = hk.cell;
        }
        float wt[8];
        trilerp_weights(hk.p, wt);
        surf_sums_add(sums, wt, dds, d_sa, d_raw);
    }
    cnt.atomic_adds += flush(cur, y, sums);
    if (pc.bg.v[0].learn != 0u) {
        precise vec3 g_bg = (d_c * t_last) * t_bg;
        BACKGROUND_GRAD_ADD(pc.bg, g_bg);
    }
    TRAIN_COUNTS_SUBGROUP_ADD(pc.stats.v[0], cnt);
}
