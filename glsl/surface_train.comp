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
// (3 floats); bg (the background composited behind the last hit: C = Σ w_j c_j + T·bg.rgb).
// Outputs: grad_delta, grad_opacity, grad_sh += (float atomics), touched list (step buffer);
// when bg.learn ≠ 0, bg.grad += Σ_rays dL/dC·T (subgroup-reduced float atomics);
// out_rays[r] = RayLoss (squared error, entropy, consistency, hits composited); stats
// (TrainCounts) += cells read (live cells: links and δ loaded), cubic solves, solves culled
// (min/max or segment), hits composited, hits cut by truncation, guarded hits, gradient atomic
// adds, blocks skipped (subgroup-reduced).
// CPU twin: `cpu::surface_train::train`.
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

// What the backward pass needs of a composited hit (surface_train records ≤ SURF_MAX_HITS).
struct HitRec {
    ivec3 cell;
    vec3 p;      // local hit point
    float depth; // t0 + s (voxels)
    float sa;    // σα
    float at;    // α̃
    float gam;   // γ_a(k), k the hit's truncation count
    uint sid;    // its structure along the ray (0 unless the count restarts)
    vec3 raw;    // raw colour
    vec3 draw;   // ∂raw/∂s
    float dsa;   // ∂σα/∂s
    float f1;    // f′(s)
    bool guard;  // the f′ guard drops the δ gradient
};

// rec[j] = v and rec[k] with a data-dependent slot, through constant indices: the records stay in
// registers (an indexed local array is kept in memory and gathered lane by lane on SIMD-per-lane
// drivers such as lavapipe).
void set_hit(inout HitRec rec[SURF_MAX_HITS], uint j, HitRec v) {
    [[unroll]] for (uint q = 0u; q < SURF_MAX_HITS; q++) {
        if (q == j) rec[q] = v;
    }
}

HitRec get_hit(HitRec rec[SURF_MAX_HITS], uint k) {
    HitRec v = rec[0];
    [[unroll]] for (uint q = 1u; q < SURF_MAX_HITS; q++) {
        if (q == k) v = rec[q];
    }
    return v;
}

// ∂w_i/∂s at local point p moving along unit direction d.
void trilerp_dwds(vec3 p, vec3 d, out float dw[8]) {
    vec3 q = vec3(1.0) - p;
    for (uint i = 0u; i < 8u; i++) {
        bool bx = ((i >> 2u) & 1u) == 1u;
        bool by = ((i >> 1u) & 1u) == 1u;
        bool bz = (i & 1u) == 1u;
        float fx = bx ? p.x : q.x;
        float fy = by ? p.y : q.y;
        float fz = bz ? p.z : q.z;
        float sx = bx ? 1.0 : -1.0;
        float sy = by ? 1.0 : -1.0;
        float sz = bz ? 1.0 : -1.0;
        precise float v = sx * fy * fz * d.x + fx * sy * fz * d.y + fx * fy * sz * d.z;
        dw[i] = v;
    }
}

// Adds a cell's per-corner gradient sums (one atomic per corner and parameter that received a
// non-zero term), touches the corners that get one, clears the sums and masks; returns the atomic
// adds. Which corners and parameters get an add is read from the masks of non-zero terms (bit i
// of nz_d / nz_a, bit 3i + ch of nz_c), set from single products: a sum's exact zero could
// depend on whether the compiler fused its additions, a product's cannot.
uint flush(ivec3 cell, float y[9], inout float acc_d[8], inout float acc_a[8], inout vec3 acc_c[8],
           inout uint nz_d, inout uint nz_a, inout uint nz_c) {
    if (cell.x < 0) return 0u;
    int lk[8];
    cell_links(pc.links, uvec3(pc.n), cell, lk);
    uint adds = 0u;
    for (uint i = 0u; i < 8u; i++) {
        float gd = acc_d[i];
        float ga = acc_a[i];
        vec3 gc = acc_c[i];
        acc_d[i] = 0.0;
        acc_a[i] = 0.0;
        acc_c[i] = vec3(0.0);
        bool bd = ((nz_d >> i) & 1u) != 0u;
        bool ba = ((nz_a >> i) & 1u) != 0u;
        uint bc = (nz_c >> (3u * i)) & 7u;
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
    nz_d = 0u;
    nz_a = 0u;
    nz_c = 0u;
    return adds;
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
    vec3 scale = prm.scale;
    vec3 offset = prm.offset;
    float a = prm.a;
    float stop_thresh = prm.stop_thresh;
    uint nl = min(prm.n_levels, SURF_MAX_LEVELS);
    float lv[SURF_MAX_LEVELS];
    for (uint i = 0u; i < SURF_MAX_LEVELS; i++) lv[i] = i < nl ? prm.levels[i] : 0.0;
    vec3 og, dn;
    surf_ray(ro, rd, scale, offset, og, dn);
    precise vec3 dg = rd * scale;
    precise float len2 = dg.x * dg.x + dg.y * dg.y + dg.z * dg.z;
    float len = sqrt(len2);
    float inv_len = len > 0.0 ? 1.0 / len : 0.0;
    float y[9];
    sh_basis(ray_unit(rd), y);
    TrainCounts cnt = TRAIN_COUNTS_ZERO;

    // Forward walk, recording the composited hits (registers: HitRec, set_hit).
    HitRec rec[SURF_MAX_HITS];
    float T = 1.0;
    uint j = 0u;
    // The truncation count: j itself, or with counting per structure the hits since the ray last
    // entered level 0 (surf_restart).
    uint k = 0u;
    uint sid = 0u;
    bool per_structure = prm.count_per_structure != 0u;
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
        ivec3 l = cell.piece.cell;
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
        float cmin = min(min(min(cell.c[0], cell.c[1]), min(cell.c[2], cell.c[3])),
                         min(min(cell.c[4], cell.c[5]), min(cell.c[6], cell.c[7])));
        float cmax = max(max(max(cell.c[0], cell.c[1]), max(cell.c[2], cell.c[3])),
                         max(max(cell.c[4], cell.c[5]), max(cell.c[6], cell.c[7])));
        // A cell's list holds its SURF_CELL_KEEP first hits (more are reached only when counting
        // per structure skips truncated hits; they are dropped).
        uint nk = min(nh, SURF_CELL_KEEP);
        for (uint h = 0u; h < nk; h++) {
            precise float s_hit = surf_pop(hs);
            surf_restart(per_structure, s_hit, outer, k);
            // A truncated hit (γ = 0) ends the ray, or with counting per structure is passed
            // over (a later structure restarts the count); a full record ends it.
            if (float(k) >= a || j >= SURF_MAX_HITS) {
                cnt.cut++;
                if (per_structure && j < SURF_MAX_HITS && T >= SURF_PASS_MIN_T) continue;
                done = true;
                break;
            }
            precise vec3 p = clamp(cell.q0 + s_hit * dn, 0.0, 1.0);
            float wt[8];
            trilerp_weights(p, wt);
            float dw[8];
            trilerp_dwds(p, dn, dw);
            precise float sa = 0.0;
            [[unroll]] for (int i = 0; i < 8; i++) sa += wt[i] * pc.opacity.v[cell.lk[i]];
            float gam = surf_gamma(a, k);
            precise float at = surf_alpha(sa) * gam;
            // Shading and the derivatives along the ray the backward pass needs.
            precise vec3 raw = vec3(0.5);
            precise vec3 draw = vec3(0.0);
            precise float dsa = 0.0;
            precise float f1 = 0.0;
            [[unroll]] for (int i = 0; i < 8; i++) {
                uint row = uint(cell.lk[i]);
                dsa += dw[i] * pc.opacity.v[row];
                f1 += dw[i] * cell.c[i];
                float shv[27];
                SH27_LOAD(pc.sh, row, shv);
                [[unroll]] for (uint ch = 0u; ch < 3u; ch++) {
                    precise float v = 0.0;
                    [[unroll]] for (uint k = 0u; k < 9u; k++) v += y[k] * shv[ch * 9u + k];
                    raw[ch] += wt[i] * v;
                    draw[ch] += dw[i] * v;
                }
            }
            HitRec hr;
            hr.cell = l;
            hr.p = p;
            precise float depth = t0 + s_hit;
            hr.depth = depth;
            hr.sa = sa;
            hr.at = at;
            hr.gam = gam;
            // A restarted count (k = 0 after the first record) starts the next structure.
            if (k == 0u && j > 0u) sid++;
            hr.sid = sid;
            hr.raw = raw;
            hr.draw = draw;
            hr.dsa = dsa;
            hr.f1 = f1;
            hr.guard = abs(f1) <= FPRIME_GUARD * (cmax - cmin);
            set_hit(rec, j, hr);
            j++;
            k++;
            cnt.hits++;
            precise float tn = T * (1.0 - at);
            T = tn;
            if (T < stop_thresh) {
                done = true;
                break;
            }
        }
    }
    uint nh = j;
    cnt.cells = walk.counts.cells;
    cnt.solves = walk.counts.solves;
    cnt.culled = walk.counts.culled;
    cnt.blocks_skipped = walk.counts.blocks_skipped;

    // Compositing from the records, and the squared error. Loops over the records run over all
    // SURF_MAX_HITS slots with a guard, unrolled, so that every index is a constant.
    float tr[SURF_MAX_HITS + 1u];
    float wj[SURF_MAX_HITS];
    tr[0] = 1.0;
    precise vec3 color = vec3(0.0);
    [[unroll]] for (uint k = 0u; k < SURF_MAX_HITS; k++) {
        wj[k] = 0.0;
        tr[k + 1u] = tr[k];
        if (k >= nh) continue;
        precise float wk = tr[k] * rec[k].at;
        wj[k] = wk;
        color += wk * max(rec[k].raw, vec3(0.0));
        precise float tn = tr[k] * (1.0 - rec[k].at);
        tr[k + 1u] = tn;
    }
    float t_last = tr[SURF_MAX_HITS]; // = tr[nh]: the slots past nh copy it
    vec3 bg = pc.bg.v[0].rgb;
    precise vec3 total = color + t_last * bg;
    precise vec3 diff = total - target;
    RayLoss o;
    precise float sq = diff.x * diff.x + diff.y * diff.y + diff.z * diff.z;
    o.sq_err = omega * sq;
    o.entropy = 0.0;
    o.consistency = 0.0;
    o.hits = nh;
    float grad_scale = prm.grad_scale * omega;
    precise vec3 d_c = grad_scale * diff;
    bool learn_bg = pc.bg.v[0].learn != 0u;

    // Entropy of the normalised weights and ∂(λH·LH)/∂w_j.
    float lambda_h = prm.lambda_h * omega;
    float e[SURF_MAX_HITS];
    [[unroll]] for (uint k = 0u; k < SURF_MAX_HITS; k++) e[k] = 0.0;
    precise float wsum = 0.0;
    [[unroll]] for (uint k = 0u; k < SURF_MAX_HITS; k++) {
        if (k < nh) wsum += wj[k];
    }
    if (lambda_h != 0.0 && wsum > 1e-8) {
        precise float H = 0.0;
        [[unroll]] for (uint k = 0u; k < SURF_MAX_HITS; k++) {
            if (k < nh && wj[k] > 0.0) {
                precise float pk = wj[k] / wsum;
                H -= pk * log(pk);
            }
        }
        o.entropy = omega * H;
        [[unroll]] for (uint k = 0u; k < SURF_MAX_HITS; k++) {
            if (k < nh && wj[k] > 0.0) {
                precise float ek = -lambda_h * (log(wj[k] / wsum) + H) / wsum;
                e[k] = ek;
            }
        }
    }
    // Lc per structure (one, unless the truncation count restarts): depths in scene units, the
    // structure's mode = its first largest weight; ∂/∂t_mode is summed apart per structure (the
    // same additions in the same order). Structures are runs of records with one sid, so each
    // pass below is one sweep over the slots.
    float lambda_c = prm.lambda_c * omega;
    float d_t[SURF_MAX_HITS];
    [[unroll]] for (uint k = 0u; k < SURF_MAX_HITS; k++) d_t[k] = 0.0;
    if (lambda_c != 0.0 && nh > 1u) {
        // Each slot's mode and the mode's depth: running forward over its run, then handed back
        // from the run's last slot.
        uint mk[SURF_MAX_HITS];
        float tmk[SURF_MAX_HITS];
        uint m = 0u;
        float wm = -1.0;
        float tm = 0.0;
        [[unroll]] for (uint k = 0u; k < SURF_MAX_HITS; k++) {
            bool starts = k == 0u || rec[k].sid != rec[k == 0u ? 0u : k - 1u].sid;
            if (k < nh && (starts || wj[k] > wm)) {
                m = k;
                wm = wj[k];
                tm = rec[k].depth;
            }
            mk[k] = m;
            tmk[k] = tm;
        }
        [[unroll]] for (uint k = SURF_MAX_HITS - 1u; k > 0u; k--) {
            if (k < nh && rec[k].sid == rec[k - 1u].sid) {
                mk[k - 1u] = mk[k];
                tmk[k - 1u] = tmk[k];
            }
        }
        // The terms, and per run −Σ λ·sign over its other slots (left at each slot as the run's
        // sum so far, then handed back from the run's last slot to its mode).
        precise float lc = 0.0;
        precise float acc = 0.0;
        float tot[SURF_MAX_HITS];
        [[unroll]] for (uint k = 0u; k < SURF_MAX_HITS; k++) {
            tot[k] = 0.0;
            if (k >= nh) continue;
            if (k == 0u || rec[k].sid != rec[k == 0u ? 0u : k - 1u].sid) acc = 0.0;
            if (k != mk[k]) {
                precise float tmode = tmk[k] * inv_len;
                precise float dk = rec[k].depth * inv_len - tmode;
                lc += abs(dk);
                float sg = dk > 0.0 ? 1.0 : (dk < 0.0 ? -1.0 : 0.0);
                precise float a1 = lambda_c * sg;
                d_t[k] = a1;
                precise float a2 = acc - lambda_c * sg;
                acc = a2;
            }
            tot[k] = acc;
        }
        [[unroll]] for (uint k = SURF_MAX_HITS - 1u; k > 0u; k--) {
            if (k < nh && rec[k].sid == rec[k - 1u].sid) tot[k - 1u] = tot[k];
        }
        [[unroll]] for (uint k = 0u; k < SURF_MAX_HITS; k++) {
            if (k < nh && mk[k] == k) d_t[k] = tot[k];
        }
        o.consistency = omega * lc;
    }
    pc.out_rays.v[r] = o;

    // Reverse pass: colour and entropy seen from behind each hit (behind the last: the
    // background); the gradients of consecutive hits in one cell are summed per corner and
    // flushed when the cell changes. Unrolled over the slots (constant indices) with the flush
    // outside: a slot whose cell differs from the running one hands the running sums over first.
    precise vec3 s_c = bg;
    precise float s_e = 0.0;
    ivec3 cur = ivec3(-1);
    float acc_d[8];
    float acc_a[8];
    vec3 acc_c[8];
    [[unroll]] for (uint i = 0u; i < 8u; i++) {
        acc_d[i] = 0.0;
        acc_a[i] = 0.0;
        acc_c[i] = vec3(0.0);
    }
    uint nz_d = 0u, nz_a = 0u, nz_c = 0u;
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
        float at = hk.at;
        vec3 raw = hk.raw;
        vec3 col = max(raw, vec3(0.0));
        precise float d_at = trk * (ek - s_e);
        [[unroll]] for (uint ch = 0u; ch < 3u; ch++) {
            precise float term = d_c[ch] * trk * (col[ch] - s_c[ch]);
            d_at += term;
        }
        precise vec3 d_raw = mix(vec3(0.0), d_c * wk, greaterThan(raw, vec3(0.0)));
        s_c = at * col + (1.0 - at) * s_c;
        s_e = at * ek + (1.0 - at) * s_e;
        // ∂L/∂σα, and ∂L/∂s: opacity and colour move with the hit point, and the depth (Lc).
        float sa = hk.sa;
        float ex = exp(-max(sa, 0.0));
        precise float d_sa = sa > 0.0 ? d_at * hk.gam * ex : 0.0;
        precise float dl_ds = d_sa * hk.dsa + dtk * inv_len;
        [[unroll]] for (uint ch = 0u; ch < 3u; ch++) dl_ds += d_raw[ch] * hk.draw[ch];
        bool guarded = hk.guard;
        if (guarded) cnt.guarded++;
        precise float dds = (guarded || dl_ds == 0.0) ? 0.0 : -dl_ds / hk.f1;
        if (hk.cell != cur) {
            cnt.atomic_adds += flush(cur, y, acc_d, acc_a, acc_c, nz_d, nz_a, nz_c);
            cur = hk.cell;
        }
        float wt[8];
        trilerp_weights(hk.p, wt);
        [[unroll]] for (uint i = 0u; i < 8u; i++) {
            precise float td = wt[i] * dds;
            precise float ta = wt[i] * d_sa;
            precise vec3 tc = wt[i] * d_raw;
            precise float gd = acc_d[i] + td;
            acc_d[i] = gd;
            precise float ga = acc_a[i] + ta;
            acc_a[i] = ga;
            precise vec3 gc = acc_c[i] + tc;
            acc_c[i] = gc;
            nz_d |= uint(td != 0.0) << i;
            nz_a |= uint(ta != 0.0) << i;
            nz_c |= (uint(tc.x != 0.0) | (uint(tc.y != 0.0) << 1u) | (uint(tc.z != 0.0) << 2u)) << (3u * i);
        }
    }
    cnt.atomic_adds += flush(cur, y, acc_d, acc_a, acc_c, nz_d, nz_a, nz_c);
    if (learn_bg) BACKGROUND_GRAD_ADD(pc.bg, d_c * t_last);
    TRAIN_COUNTS_SUBGROUP_ADD(pc.stats.v[0], cnt);
}
