// surface.glsl — stage-2 (αSurf) surface rendering pieces (method.md §3.2, §5): the ray in grid
// units, a cell's entry/exit points, the sorted front-face hits of every level in one cell, and
// the truncation count and weight γ_a(j). Pure functions (no buffer access): the kernels read the grid.
// Rust twin: src/math/surface.rs (same operations in the same order; `precise` everywhere the
// twin rounds each operation).
//
// Conventions: grid = p·scale + offset; the grid-space direction is normalised, so t and s are in
// voxels. A cell's piece [t0, t1] of the DDA walk has entry point q0 = P(t0) − l and exit point
// q1 = P(t1) − l with P(t) = og + t·dn, clamped to [0,1]³, and exactly 0 or 1 on every axis whose
// cell face the DDA crosses at that t (the walk's own plane time): the exit of one cell and the
// entry of the next are the same point of their shared face, edge or corner, a level's value there
// is the same trilerp of the shared corners on both sides, and a crossing there belongs to the
// entered cell, which is given the sign before it (surf_cell_hits' bpos/bneg).
#ifndef SURFACE_GLSL
#define SURFACE_GLSL

#include "dda.glsl"
#include "cubic.glsl"
#include "trilerp.glsl"
#include "sh.glsl"

// SURF_MAX_LEVELS (at most this many levels τ_i), SURF_SEGMENT_MARGIN: src/abi/consts.rs.
const float SURF_PI = 3.14159265358979;

// Per-ray output of surface_fwd: SurfOut (src/abi/buffers.rs, abi.glsl).

// Scene ray (ro, rd) → grid origin og = ro·scale + offset and unit grid direction dn.
void surf_ray(vec3 ro, vec3 rd, vec3 scale, vec3 offset, out vec3 og, out vec3 dn) {
    precise vec3 o = ro * scale + offset;
    precise vec3 dg = rd * scale;
    og = o;
    dn = ray_unit(dg);
}

// Local coordinates in cell l of P(t) = og + t·dn, clamped to [0,1]³; an axis whose lower or upper
// cell plane the walk w crosses at exactly t ((plane − o)·inv, dda_next's expression) is put
// exactly on that face.
vec3 surf_local(Dda w, vec3 og, vec3 dn, float t, ivec3 l) {
    precise vec3 p = og + t * dn;
    precise vec3 q = clamp(p - vec3(l), 0.0, 1.0);
    precise vec3 tlo = (vec3(l) - w.o) * w.inv;
    precise vec3 thi = (vec3(l + 1) - w.o) * w.inv;
    [[unroll]] for (int a = 0; a < 3; a++) {
        if (w.step[a] != 0) {
            if (tlo[a] == t) q[a] = 0.0;
            else if (thi[a] == t) q[a] = 1.0;
        }
    }
    return q;
}

// Hits a cell's list keeps: its SURF_CELL_KEEP smallest (the count still covers them all). A kernel
// that composites at most K hits per ray may define it as K before including this file
// (surface_train: its SURF_MAX_HITS; 8 by default); surface_fwd, with no bound on a, keeps
// every hit: 16 (≤ 2 rising crossings per level, as crossings alternate, × 8 levels).
#ifndef SURF_CELL_KEEP
#define SURF_CELL_KEEP 8u
#endif
// An empty slot of a hit list (above every s < L).
const float SURF_NO_HIT = 3.402823466e38;

// Inserts s into the ascending list hs (empty slots SURF_NO_HIT, the largest value dropped when
// all SURF_CELL_KEEP are taken) by one branchless compare-exchange pass over constant indices: hs
// stays in registers. (A data-dependent index, as in a shifting insert, makes SIMD-per-lane
// drivers such as lavapipe keep the array in memory and gather lane by lane, docs/tuning.md.)
// Equal values are interchangeable, so ties need no rule.
void surf_insert(inout float hs[SURF_CELL_KEEP], inout uint n, float s) {
    float v = s;
    [[unroll]] for (uint k = 0u; k < SURF_CELL_KEEP; k++) {
        float lo = min(hs[k], v);
        v = max(hs[k], v);
        hs[k] = lo;
    }
    n++;
}

// The smallest hit of the list, removed (the others shift down; constant indices).
float surf_pop(inout float hs[SURF_CELL_KEEP]) {
    float s = hs[0];
    [[unroll]] for (uint k = 0u; k + 1u < SURF_CELL_KEEP; k++) hs[k] = hs[k + 1u];
    hs[SURF_CELL_KEEP - 1u] = SURF_NO_HIT;
    return s;
}

// The smallest and largest of a cell's 8 corner values (x, y).
vec2 surf_cell_range(float c[8]) {
    float cmin = min(min(min(c[0], c[1]), min(c[2], c[3])), min(min(c[4], c[5]), min(c[6], c[7])));
    float cmax = max(max(max(c[0], c[1]), max(c[2], c[3])), max(max(c[4], c[5]), max(c[6], c[7])));
    return vec2(cmin, cmax);
}

// Min/max culling: bit i set when level lv[i] (i < nl) lies within [min c, max c]; only those
// levels can cross the cell.
uint surf_level_mask(float c[8], float lv[SURF_MAX_LEVELS], uint nl) {
    vec2 range = surf_cell_range(c);
    uint m = 0u;
    [[unroll]] for (uint i = 0u; i < SURF_MAX_LEVELS; i++) {
        if (i < nl && range.x <= lv[i] && lv[i] <= range.y) m |= 1u << i;
    }
    return m;
}

// Relative margin of segment culling (surf_segment_mask): SURF_SEGMENT_MARGIN.

// Segment culling: the levels of `mask` (from surf_level_mask) that can cross the ray's piece of
// the cell, corners c, entry/exit points q0/q1, cc = cubic_cell(c, q0, d), length L. Along the
// piece δ − τ is the cubic f(s) = b0 + C1·s + C2·s² + C3·s³, bounded by its Bernstein
// coefficients on [0, L] (convex hull): b0 = f(0), b1 = b0 + C1L/3, b2 = b0 + (2·C1L + C2L²)/3,
// b3 = b0 + C1L + C2L² + C3L³; the solver also reads the exit value e = δ(q1) − τ. A level is
// dropped when b0..b3 and e all exceed m or all lie below −m,
// m = SURF_SEGMENT_MARGIN·(|b0| + |C1L| + |C2L²| + |C3L³| + max|c| + |τ|): f then stays that far
// from 0 on the piece, and the solver's own values (its f(0) and e, f at the critical points,
// snapped to 0 within 2^-22 of their magnitude) differ from these by a few rounding units of the
// same magnitudes, so it would find no crossing (tested against the solver in the twin). A level
// dropped here saves its solve; a cell left without levels is walked past like an empty one.
uint surf_segment_mask(float c[8], vec3 cc, vec3 q0, vec3 q1, float L, float lv[SURF_MAX_LEVELS],
                       uint mask) {
    float v0 = trilerp(c, q0);
    float v1 = trilerp(c, q1);
    precise float a1 = cc.x * L;
    precise float a2 = (cc.y * L) * L;
    precise float a3 = ((cc.z * L) * L) * L;
    float cabs = 0.0;
    for (int i = 0; i < 8; i++) cabs = max(cabs, abs(c[i]));
    precise float size = ((abs(a1) + abs(a2)) + abs(a3)) + cabs;
    uint keep = 0u;
    [[unroll]] for (uint i = 0u; i < SURF_MAX_LEVELS; i++) {
        if ((mask & (1u << i)) == 0u) continue;
        float tau = lv[i];
        precise float b0 = v0 - tau;
        precise float b1 = b0 + a1 / 3.0;
        precise float b2 = b0 + (2.0 * a1 + a2) / 3.0;
        precise float b3 = ((b0 + a1) + a2) + a3;
        precise float e = v1 - tau;
        precise float m = SURF_SEGMENT_MARGIN * ((abs(b0) + size) + abs(tau));
        float lo = min(min(min(b0, b1), min(b2, b3)), e);
        float hi = max(max(max(b0, b1), max(b2, b3)), e);
        if (!(lo > m || hi < -m)) keep |= 1u << i;
    }
    return keep;
}

// Appends a front crossing of level 0 to `outer` (its ≤ 2 in a cell: rising and falling
// crossings alternate, and a cubic has ≤ 3 roots).
void surf_outer_add(inout vec2 outer, float s) {
    if (outer.x == SURF_NO_HIT) outer.x = s;
    else if (outer.y == SURF_NO_HIT) outer.y = s;
}

// Front-face (rising) crossings in one cell of the levels in `mask` (from surf_segment_mask):
// their count, and the SURF_CELL_KEEP smallest s ∈ [0, L) in ascending order in hs (read them with
// surf_pop); corners c (paper order), cc = cubic_cell(c, q0, d) (C1..C3, formed once per cell),
// entry/exit points q0/q1. Each level solves with its own exact end values and the sign before
// the entry point (bit i of bpos/bneg; neither: unknown), and leaves the sign before the exit in
// epos/eneg (for the next cell when it starts at this cell's t1). `outer`: level 0's front
// crossings among them, ascending (SURF_NO_HIT where there are fewer than two), for
// surf_restart.
uint surf_cell_hits(float c[8], vec3 cc, vec3 q0, vec3 q1, float L, float lv[SURF_MAX_LEVELS],
                    uint mask, uint bpos, uint bneg, out float hs[SURF_CELL_KEEP], out uint epos,
                    out uint eneg, out vec2 outer) {
    uint n = 0u;
    epos = 0u;
    eneg = 0u;
    outer = vec2(SURF_NO_HIT);
    [[unroll]] for (uint i = 0u; i < SURF_CELL_KEEP; i++) hs[i] = SURF_NO_HIT;
    while (mask != 0u) {
        uint i = uint(findLSB(mask));
        mask &= mask - 1u;
        float tau = lv[i];
        vec2 ends = vec2(cubic_trilerp_level(c, q0, tau), cubic_trilerp_level(c, q1, tau));
        float before = ((bpos >> i) & 1u) != 0u ? 1.0 : (((bneg >> i) & 1u) != 0u ? -1.0 : 0.0);
        CubicCrossings x = cubic_solve(cc, ends, L, before);
        if (x.n > 0u && (x.rising & 1u) != 0u) {
            surf_insert(hs, n, x.s.x);
            if (i == 0u) surf_outer_add(outer, x.s.x);
        }
        if (x.n > 1u && (x.rising & 2u) != 0u) {
            surf_insert(hs, n, x.s.y);
            if (i == 0u) surf_outer_add(outer, x.s.y);
        }
        if (x.n > 2u && (x.rising & 4u) != 0u) {
            surf_insert(hs, n, x.s.z);
            if (i == 0u) surf_outer_add(outer, x.s.z);
        }
        float e = cubic_exit_sign(x, ends.x, before);
        if (e > 0.0) epos |= 1u << i;
        else if (e < 0.0) eneg |= 1u << i;
    }
    return n;
}

// The truncation count of a ray (`mode`: SurfParams::truncation_count, SURF_COUNT_*): k hits
// counted, a hit truncated (γ = 0) from k ≥ limit (a at the start), `structures` entered so far.
// Counting per structure, a popped hit s that is one of the cell's front crossings of level 0
// (`outer`; the outermost level, as levels increase) is where the ray enters a structure from
// outside every level set, so k restarts at 0 there with limit a (SURF_COUNT_STRUCTURE, and the
// first structure of SURF_COUNT_THROUGH) or min(a, 1) (the structures behind it with
// SURF_COUNT_THROUGH): each structure along the ray gets its own first hits, while the inner
// levels of one structure are still truncated. A matched value is consumed: of two equal hits one
// restarts the count. Twin: math::surface::RayCount::restart.
void surf_restart(uint mode, float a, float s, inout vec2 outer, inout uint k, inout float limit,
                  inout uint structures) {
    if (mode == SURF_COUNT_RAY) return;
    if (s == outer.x) {
        outer.x = SURF_NO_HIT;
    } else if (s == outer.y) {
        outer.y = SURF_NO_HIT;
    } else {
        return;
    }
    k = 0u;
    limit = (mode == SURF_COUNT_THROUGH && structures > 0u) ? min(a, 1.0) : a;
    structures++;
}

// Truncation weight γ_a(j) = ½(1 − cos(π·clamp(a − j, 0, 1))): exactly 1 for j ≤ a − 1 and
// exactly 0 for j ≥ a.
float surf_gamma(float a, uint j) {
    precise float u = clamp(a - float(j), 0.0, 1.0);
    if (u >= 1.0) return 1.0;
    if (u <= 0.0) return 0.0;
    precise float g = 0.5 * (1.0 - cos(SURF_PI * u));
    return g;
}

// α = 1 − exp(−max(σα, 0)) (no step length).
float surf_alpha(float sa) {
    precise float a = 1.0 - exp(-max(sa, 0.0));
    return a;
}

#endif
