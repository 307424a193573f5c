// Ray/level-set intersection inside one cell (method.md §3.2, §5). CPU twin: src/math/cubic.rs
// (same operations in the same order; `precise` keeps the compiler from re-associating or
// contracting, so the twin agrees to the last bit wherever fma, division and sqrt are exact).
//
// Corners c[8] in the paper's order, index 4a + 2b + c (a = x bit, b = y bit, c = z bit); entry
// point o in [0,1]^3; unit direction d in voxel units; segment length L.
//   cubic_cell(c, o, d)      -> vec3(C1, C2, C3), shared by every level of the cell
//   cubic_level_ends(c, o, d, L, tau) -> vec2(f(0), f(L)): trilerps of (corner - tau) at the entry
//                               and exit points (a level through a face is decided exactly)
//   cubic_solve(C123, ends, L, before) -> sign-change crossings of f on [0, L), sorted, merged;
//                               before = sign of f just before s = 0 (0: unknown)
//   cubic_exit_sign(x, f0, before) -> sign of f just before s = L (the next cell's `before`)
#ifndef CUBIC_GLSL
#define CUBIC_GLSL
#extension GL_EXT_control_flow_attributes : require

// CUBIC_MERGE_EPS, CUBIC_MAX_ITERS, CUBIC_STEP_TOL, CUBIC_SNAP, CUBIC_CRIT_SNAP, CUBIC_MAX_L:
// src/abi/consts.rs (abi.glsl).

// Up to three crossings: s[i] for i < n, bit i of `rising` set when f - tau goes from < 0 to > 0.
struct CubicCrossings {
    uint n;
    vec3 s;
    uint rising;
};

// FMA-shaped lerp, exact at t = 0 and t = 1.
float cubic_lerp(float a, float b, float t) {
    precise float r = fma(t, b, fma(-t, a, a));
    return r;
}

// C1, C2, C3 from the corners minus corner 000 (coefficients of s^1..s^3 ignore a constant shift;
// the shift keeps nearly flat cells exact), then method.md's lerp/FMA lines.
vec3 cubic_cell(float c[8], vec3 o, vec3 d) {
    precise float w0 = c[0] - c[0];
    precise float w1 = c[1] - c[0];
    precise float w2 = c[2] - c[0];
    precise float w3 = c[3] - c[0];
    precise float w4 = c[4] - c[0];
    precise float w5 = c[5] - c[0];
    precise float w6 = c[6] - c[0];
    precise float w7 = c[7] - c[0];
    float m00 = cubic_lerp(w0, w1, o.z);
    float m01 = cubic_lerp(w2, w3, o.z);
    float m10 = cubic_lerp(w4, w5, o.z);
    float m11 = cubic_lerp(w6, w7, o.z);
    precise float e00 = w1 - w0;
    precise float e01 = w3 - w2;
    precise float e10 = w5 - w4;
    precise float e11 = w7 - w6;
    float n0 = cubic_lerp(m00, m01, o.y);
    float n1 = cubic_lerp(m10, m11, o.y);
    precise float k0 = fma(d.y, m01 - m00, d.z * cubic_lerp(e00, e01, o.y));
    precise float k1 = fma(d.y, m11 - m10, d.z * cubic_lerp(e10, e11, o.y));
    precise float dyz = d.y * d.z;
    precise float h0 = dyz * (e01 - e00);
    precise float h1 = dyz * (e11 - e10);
    precise float c3 = d.x * (h1 - h0);
    precise float c2 = fma(d.x, k1 - k0, cubic_lerp(h0, h1, o.x));
    precise float c1 = fma(d.x, n1 - n0, cubic_lerp(k0, k1, o.x));
    return vec3(c1, c2, c3);
}

// delta(p) - tau: the trilerp at p of (corner - tau).
float cubic_trilerp_level(float c[8], vec3 o, float tau) {
    precise float t0 = c[0] - tau;
    precise float t1 = c[1] - tau;
    precise float t2 = c[2] - tau;
    precise float t3 = c[3] - tau;
    precise float t4 = c[4] - tau;
    precise float t5 = c[5] - tau;
    precise float t6 = c[6] - tau;
    precise float t7 = c[7] - tau;
    float m00 = cubic_lerp(t0, t1, o.z);
    float m01 = cubic_lerp(t2, t3, o.z);
    float m10 = cubic_lerp(t4, t5, o.z);
    float m11 = cubic_lerp(t6, t7, o.z);
    return cubic_lerp(cubic_lerp(m00, m01, o.y), cubic_lerp(m10, m11, o.y), o.x);
}

// Exit point o + L d, clamped to the cell; the coordinate nearest a face is snapped onto it when
// within CUBIC_SNAP (undoes rounding; the level through that face is then decided by the same
// corner values as in the next cell).
vec3 cubic_exit_point(vec3 o, vec3 d, float L) {
    precise vec3 p = fma(vec3(L), d, o);
    vec3 q = clamp(p, 0.0, 1.0);
    precise vec3 dq = min(q, 1.0 - q);
    if (dq.x <= dq.y && dq.x <= dq.z) {
        if (dq.x <= CUBIC_SNAP) q.x = q.x > 0.5 ? 1.0 : 0.0;
    } else if (dq.y <= dq.z) {
        if (dq.y <= CUBIC_SNAP) q.y = q.y > 0.5 ? 1.0 : 0.0;
    } else {
        if (dq.z <= CUBIC_SNAP) q.z = q.z > 0.5 ? 1.0 : 0.0;
    }
    return q;
}

// (f(0), f(L)) = (C0 - tau, delta(exit) - tau).
vec2 cubic_level_ends(float c[8], vec3 o, vec3 d, float L, float tau) {
    return vec2(cubic_trilerp_level(c, o, tau), cubic_trilerp_level(c, cubic_exit_point(o, d, L), tau));
}

// c = (C0, C1, C2, C3): Horner with FMAs.
float cubic_eval(vec4 c, float s) {
    precise float r = fma(fma(fma(c.w, s, c.z), s, c.y), s, c.x);
    return r;
}

float cubic_eval_deriv(vec4 c, float s) {
    precise float r = fma(fma(3.0 * c.w, s, 2.0 * c.z), s, c.y);
    return r;
}

// f at a critical point, snapped to 0 within its rounding noise: the sign walk then decides a
// tangent touch (no crossing) or a triple root (one crossing) from the neighbouring values.
float cubic_crit_value(vec4 c, float s) {
    float v = cubic_eval(c, s);
    precise float mag = fma(fma(fma(abs(c.w), s, abs(c.z)), s, abs(c.y)), s, abs(c.x));
    return abs(v) <= CUBIC_CRIT_SNAP * mag ? 0.0 : v;
}

// Power of two bringing m (> 0, finite) into [0.5, 1), clamped to a normal float.
float cubic_pow2_scale(float m) {
    int e = int((floatBitsToUint(m) >> 23) & 0xffu);
    uint se = uint(clamp(253 - e, 1, 254));
    return uintBitsToFloat(se << 23);
}

// Safeguarded Newton/bisection (rtsafe) in the bracket (lo, hi) with end values of strictly
// opposite signs; regula-falsi start; stops when a step is <= tol.
float cubic_refine(vec4 c, float lo, float hi, float flo, float fhi, float tol) {
    bool neg_lo = flo < 0.0;
    precise float x = lo + (hi - lo) * (flo / (flo - fhi));
    x = clamp(x, lo, hi);
    precise float dxold = hi - lo;
    precise float dx = dxold;
    float f = cubic_eval(c, x);
    float fp = cubic_eval_deriv(c, x);
    for (uint it = 0u; it < CUBIC_MAX_ITERS; ++it) {
        if (f == 0.0) break;
        if ((f < 0.0) == neg_lo) {
            lo = x;
        } else {
            hi = x;
        }
        precise float ta = (x - hi) * fp - f;
        precise float tb = (x - lo) * fp - f;
        bool out_of_bracket = ta * tb >= 0.0;
        precise float f2 = 2.0 * f;
        precise float dfp = dxold * fp;
        bool slow = abs(f2) > abs(dfp);
        dxold = dx;
        if (out_of_bracket || slow) {
            dx = 0.5 * (hi - lo);
            x = lo + dx;
        } else {
            dx = f / fp;
            x = x - dx;
        }
        if (abs(dx) <= tol) break;
        f = cubic_eval(c, x);
        fp = cubic_eval_deriv(c, x);
    }
    return x;
}

// Sign walk over the monotone pieces (see solve_crossings in the twin).
// Brackets are only recorded during the walk and refined afterwards in one loop with a single
// call site, so that lanes whose roots lie in different pieces iterate together.
struct CubicWalk {
    float ps;      // sign of the last nonzero boundary value (0 before any)
    bool pending;  // a zero boundary value awaits the next nonzero value
    float zpos;    // first zero of the pending run
    CubicCrossings res; // crossings so far; those in `need` still hold a placeholder s
    uint need;     // bit k: crossing k comes from bracket (count of lower bits set)
    uint nb;       // brackets recorded
    vec4 br0;      // brackets as (lo, hi, f(lo), f(hi))
    vec4 br1;
    vec4 br2;
};

// Append (s, rising) to x (no dynamic vector indexing: it would spill on SIMD-per-lane drivers).
void cubic_push(inout CubicCrossings x, float s, bool rising) {
    uint i = x.n;
    if (i == 0u) x.s.x = s; else if (i == 1u) x.s.y = s; else x.s.z = s;
    if (rising) x.rising |= 1u << i;
    x.n = i + 1u;
}

void cubic_piece(inout CubicWalk w, float b0, float v0, float b1, float v1) {
    if (v1 == 0.0) {
        if (!w.pending) {
            w.pending = true;
            w.zpos = b1;
        }
        return;
    }
    float sg = v1 > 0.0 ? 1.0 : -1.0;
    if (w.pending) {
        if (sg != w.ps) cubic_push(w.res, w.zpos, v1 > 0.0);
        w.pending = false;
    } else if (sg != w.ps) {
        w.need |= 1u << w.res.n;
        vec4 br = vec4(b0, b1, v0, v1);
        if (w.nb == 0u) w.br0 = br; else if (w.nb == 1u) w.br1 = br; else w.br2 = br;
        w.nb += 1u;
        cubic_push(w.res, 0.0, v1 > 0.0);
    }
    w.ps = sg;
}

// Cluster merge and the half-open clamp s < L. CubicCrossings alternate in direction, so a cluster
// (neighbours closer than eps) changes the sign iff its count is odd; it then keeps its first.
// With at most three crossings: 0 is kept unless it opens an even cluster {0,1}; 1 only when
// alone; 2 unless it joins 1.
CubicCrossings cubic_merge(CubicCrossings x, float L) {
    float eps = CUBIC_MERGE_EPS * max(L, 1.0);
    precise float g01 = x.s.y - x.s.x;
    precise float g12 = x.s.z - x.s.y;
    bool gap01 = x.n >= 2u && g01 < eps;
    bool gap12 = x.n >= 3u && g12 < eps;
    bool keep0 = x.n >= 1u && (!gap01 || gap12);
    bool keep1 = x.n >= 2u && !gap01 && !gap12;
    bool keep2 = x.n >= 3u && !gap12;
    float below = uintBitsToFloat(floatBitsToUint(L) - 1u);
    CubicCrossings o;
    o.n = 0u;
    o.s = vec3(0.0);
    o.rising = 0u;
    if (keep0) cubic_push(o, min(x.s.x, below), (x.rising & 1u) != 0u);
    if (keep1) cubic_push(o, min(x.s.y, below), (x.rising & 2u) != 0u);
    if (keep2) cubic_push(o, min(x.s.z, below), (x.rising & 4u) != 0u);
    return o;
}

// The sign (+-1, or 0 if unknown) of f just before s = L: after the last crossing its direction,
// else the sign at s = 0 (f0, or `before` when f0 = 0); see exit_sign in the twin.
float cubic_exit_sign(CubicCrossings x, float f0, float before) {
    if (x.n > 0u) return (x.rising & (1u << (x.n - 1u))) != 0u ? 1.0 : -1.0;
    return f0 > 0.0 ? 1.0 : (f0 < 0.0 ? -1.0 : before);
}

// CubicCrossings of C3 s^3 + C2 s^2 + C1 s + C0' on [0, L); c123 = (C1, C2, C3); ends = (f(0), f(L)).
// A zero at s = 0 is this cell's crossing when the sign after it differs from `before` (the sign
// of f just before the entry point, from the previous cell of the walk; 0 when unknown: always);
// a zero at s = L is left to the next cell (see solve_crossings in the twin).
CubicCrossings cubic_solve(vec3 c123, vec2 ends, float L, float before) {
    float c0 = ends.x;
    CubicCrossings none;
    none.n = 0u;
    none.s = vec3(0.0);
    none.rising = 0u;
    if (!(L > 0.0 && L < CUBIC_MAX_L)) return none;
    // Zero, NaN or overflowed inputs: no crossings (a NaN or Inf makes the sum non-finite).
    precise float sum = abs(c0) + abs(ends.y) + abs(c123.x) + abs(c123.y) + abs(c123.z);
    if (!(sum > 0.0 && sum < 3.4028235e38)) return none;
    float m = max(max(max(abs(c0), abs(ends.y)), abs(c123.x)), max(abs(c123.y), abs(c123.z)));
    float sc = cubic_pow2_scale(m);
    precise vec4 c = vec4(c0 * sc, c123.x * sc, c123.y * sc, c123.z * sc);
    // Critical points: roots of A s^2 + 2B s + C, A = 3 C3, B = C2, C = C1 (stable formula,
    // discriminant with Kahan's FMA correction).
    precise float a = 3.0 * c.w;
    float b = c.z;
    float cq = c.y;
    precise float w = a * cq;
    precise float disc = fma(b, b, -w) + fma(-a, cq, w);
    float r1 = 0.0;
    float r2 = 0.0;
    if (disc > 0.0) {
        float sq = sqrt(disc);
        float sqs = uintBitsToFloat((floatBitsToUint(sq) & 0x7fffffffu) | (floatBitsToUint(b) & 0x80000000u));
        precise float q = -(b + sqs);
        precise float x1 = cq / q;
        r1 = (x1 > 0.0 && x1 < L) ? x1 : 0.0;
        if (a != 0.0) {
            precise float x2 = q / a;
            r2 = (x2 > 0.0 && x2 < L) ? x2 : 0.0;
        }
    }
    float b1 = min(r1, r2);
    float b2 = max(r1, r2);
    float v0 = c.x;
    float v1 = cubic_crit_value(c, b1);
    float v2 = cubic_crit_value(c, b2);
    precise float v3 = ends.y * sc;
    // Fast exit: every boundary value strictly on one side.
    if ((v0 > 0.0 && v1 > 0.0 && v2 > 0.0 && v3 > 0.0) || (v0 < 0.0 && v1 < 0.0 && v2 < 0.0 && v3 < 0.0))
        return none;
    CubicWalk wk;
    wk.ps = v0 > 0.0 ? 1.0 : (v0 < 0.0 ? -1.0 : before);
    wk.pending = v0 == 0.0;
    wk.zpos = 0.0;
    wk.res = none;
    wk.need = 0u;
    wk.nb = 0u;
    wk.br0 = vec4(0.0);
    wk.br1 = vec4(0.0);
    wk.br2 = vec4(0.0);
    cubic_piece(wk, 0.0, v0, b1, v1);
    cubic_piece(wk, b1, v1, b2, v2);
    cubic_piece(wk, b2, v2, L, v3);
    float tol = CUBIC_STEP_TOL * max(L, 1.0);
    vec3 r = vec3(0.0);
    [[dont_unroll]] for (uint j = 0u; j < wk.nb; ++j) {
        vec4 br = j == 0u ? wk.br0 : (j == 1u ? wk.br1 : wk.br2);
        float x = cubic_refine(c, br.x, br.y, br.z, br.w, tol);
        if (j == 0u) r.x = x; else if (j == 1u) r.y = x; else r.z = x;
    }
    uint j = 0u;
    if ((wk.need & 1u) != 0u) { wk.res.s.x = r.x; j = 1u; }
    if ((wk.need & 2u) != 0u) { wk.res.s.y = j == 0u ? r.x : r.y; j += 1u; }
    if ((wk.need & 4u) != 0u) wk.res.s.z = j == 0u ? r.x : (j == 1u ? r.y : r.z);
    return cubic_merge(wk.res, L);
}

#endif
