// surface.glsl — stage-2 (αSurf) surface rendering pieces (method.md §3.2, §5): the ray in grid
// units, a cell's entry/exit points, the sorted front-face hits of every level in one cell, and
// the truncation weight γ_a(j). Pure functions (no buffer access): the kernels read the grid.
// Rust twin: src/math/surface.rs (same operations in the same order; `precise` everywhere the
// twin rounds each operation).
//
// Conventions: grid = p·scale + offset; the grid-space direction is normalised, so t and s are in
// voxels. A cell's piece [t0, t1] of the DDA walk has entry point q0 = P(t0) − l and exit point
// q1 = P(t1) − l with P(t) = og + t·dn, both clamped to [0,1]³ and snapped onto the nearest face
// within CUBIC_SNAP: the exit point of one cell and the entry point of the next are the same
// global point P(t1), so a level through the shared face is decided by the same corner values on
// both sides (the crossing belongs to the entered cell: half-open [0, L)).
#ifndef SURFACE_GLSL
#define SURFACE_GLSL

#include "dda.glsl"
#include "cubic.glsl"
#include "trilerp.glsl"
#include "sh.glsl"

// At most this many levels τ_i.
const uint SURF_MAX_LEVELS = 8u;
// Bound of a cell's hit list: ≤ 3 crossings per level.
const uint SURF_MAX_CELL_HITS = 24u;
const float SURF_PI = 3.14159265358979;

// Per-ray output of surface_fwd (scalar layout, 20 bytes): rgb on white, final transmittance
// (before the background), front-face hits composited.
struct SurfOut {
    vec3 rgb;
    float transmittance;
    uint hits;
};
layout(buffer_reference, scalar, buffer_reference_align = 4) buffer SurfOutBuf { SurfOut v[]; };

// Scene ray (ro, rd) → grid origin og = ro·scale + offset and unit grid direction dn.
void surf_ray(vec3 ro, vec3 rd, vec3 scale, vec3 offset, out vec3 og, out vec3 dn) {
    precise vec3 o = ro * scale + offset;
    precise vec3 dg = rd * scale;
    og = o;
    dn = ray_unit(dg);
}

// Local coordinates in cell l of P(t) = og + t·dn, clamped to [0,1]³, the coordinate nearest a
// face snapped onto it within CUBIC_SNAP.
vec3 surf_local(vec3 og, vec3 dn, float t, ivec3 l) {
    precise vec3 p = og + t * dn;
    precise vec3 q = p - vec3(l);
    return cubic_exit_point(q, dn, 0.0);
}

// Sorted insert of s into hs[0..n) (ties keep insertion order).
void surf_insert(inout float hs[SURF_MAX_CELL_HITS], inout uint n, float s) {
    uint i = n;
    while (i > 0u && hs[i - 1u] > s) {
        hs[i] = hs[i - 1u];
        i--;
    }
    hs[i] = s;
    n++;
}

// Min/max culling: bit i set when level lv[i] (i < nl) lies within [min c, max c]; only those
// levels can cross the cell.
uint surf_level_mask(float c[8], float lv[SURF_MAX_LEVELS], uint nl) {
    float cmin = min(min(min(c[0], c[1]), min(c[2], c[3])), min(min(c[4], c[5]), min(c[6], c[7])));
    float cmax = max(max(max(c[0], c[1]), max(c[2], c[3])), max(max(c[4], c[5]), max(c[6], c[7])));
    uint m = 0u;
    [[unroll]] for (uint i = 0u; i < SURF_MAX_LEVELS; i++) {
        if (i < nl && cmin <= lv[i] && lv[i] <= cmax) m |= 1u << i;
    }
    return m;
}

// Front-face (rising) crossings in one cell of the levels in `mask` (from surf_level_mask), sorted
// by s ∈ [0, L): corners c (paper order), entry/exit points q0/q1, unit direction d. The cubic's
// C1..C3 are formed once; each level solves with its own exact end values.
uint surf_cell_hits(float c[8], vec3 q0, vec3 q1, vec3 d, float L, float lv[SURF_MAX_LEVELS],
                    uint mask, out float hs[SURF_MAX_CELL_HITS]) {
    vec3 cc = cubic_cell(c, q0, d);
    uint n = 0u;
    for (uint i = 0u; i < SURF_MAX_CELL_HITS; i++) hs[i] = 0.0;
    while (mask != 0u) {
        uint i = uint(findLSB(mask));
        mask &= mask - 1u;
        float tau = lv[i];
        vec2 ends = vec2(cubic_trilerp_level(c, q0, tau), cubic_trilerp_level(c, q1, tau));
        CubicCrossings x = cubic_solve(cc, ends, L);
        if (x.n > 0u && (x.rising & 1u) != 0u) surf_insert(hs, n, x.s.x);
        if (x.n > 1u && (x.rising & 2u) != 0u) surf_insert(hs, n, x.s.y);
        if (x.n > 2u && (x.rising & 4u) != 0u) surf_insert(hs, n, x.s.z);
    }
    return n;
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
