// trilerp.glsl — trilinear interpolation of the 8 corner values of a cell, its analytic gradient
// with respect to the local position p ∈ [0,1]³, and the 8 trilinear weights.
// Corner order i = 4a + 2b + c (a = x bit, b = y bit, c = z bit): 000, 001, …, 111, the paper's.
// Nested FMA lerps, z first, then y, then x (the same nesting as the cubic coefficients).
// Rust twin: src/math/trilerp.rs.
#ifndef TRILERP_GLSL
#define TRILERP_GLSL

// a + t·(b − a) as one FMA.
float lerp_fma(float a, float b, float t) {
    precise float r = fma(t, b - a, a);
    return r;
}

// Trilinearly interpolated value at p.
float trilerp(float c[8], vec3 p) {
    float m00 = lerp_fma(c[0], c[1], p.z);
    float m01 = lerp_fma(c[2], c[3], p.z);
    float m10 = lerp_fma(c[4], c[5], p.z);
    float m11 = lerp_fma(c[6], c[7], p.z);
    float n0 = lerp_fma(m00, m01, p.y);
    float n1 = lerp_fma(m10, m11, p.y);
    return lerp_fma(n0, n1, p.x);
}

// (value, ∂/∂p.x, ∂/∂p.y, ∂/∂p.z) at p.
vec4 trilerp_grad(float c[8], vec3 p) {
    float m00 = lerp_fma(c[0], c[1], p.z);
    float m01 = lerp_fma(c[2], c[3], p.z);
    float m10 = lerp_fma(c[4], c[5], p.z);
    float m11 = lerp_fma(c[6], c[7], p.z);
    float n0 = lerp_fma(m00, m01, p.y);
    float n1 = lerp_fma(m10, m11, p.y);
    float v = lerp_fma(n0, n1, p.x);
    float gx = n1 - n0;
    float gy = lerp_fma(m01 - m00, m11 - m10, p.x);
    float e0 = lerp_fma(c[1] - c[0], c[3] - c[2], p.y);
    float e1 = lerp_fma(c[5] - c[4], c[7] - c[6], p.y);
    float gz = lerp_fma(e0, e1, p.x);
    return vec4(v, gx, gy, gz);
}

// The 8 weights w_i(p) with trilerp(c, p) = Σ w_i c_i (they sum to 1).
void trilerp_weights(vec3 p, out float w[8]) {
    precise vec3 q = vec3(1.0) - p;
    precise float xy00 = q.x * q.y;
    precise float xy01 = q.x * p.y;
    precise float xy10 = p.x * q.y;
    precise float xy11 = p.x * p.y;
    precise float w0 = xy00 * q.z;
    precise float w1 = xy00 * p.z;
    precise float w2 = xy01 * q.z;
    precise float w3 = xy01 * p.z;
    precise float w4 = xy10 * q.z;
    precise float w5 = xy10 * p.z;
    precise float w6 = xy11 * q.z;
    precise float w7 = xy11 * p.z;
    w[0] = w0; w[1] = w1; w[2] = w2; w[3] = w3;
    w[4] = w4; w[5] = w5; w[6] = w6; w[7] = w7;
}

// ∂w_i/∂s of the weights above at p moving along the unit direction d.
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

// Links of the 8 corners of cell l in a grid of res vertices (x-major: slot (x·ny + y)·nz + z),
// in the corner order above; < 0: unallocated. Reads `links` (I32Buf, common.glsl).
void cell_links(I32Buf links, uvec3 res, ivec3 l, out int lk[8]) {
    uint ny = res.y, nz = res.z;
    uint base = (uint(l.x) * ny + uint(l.y)) * nz + uint(l.z);
    lk[0] = links.v[base];
    lk[1] = links.v[base + 1u];
    lk[2] = links.v[base + nz];
    lk[3] = links.v[base + nz + 1u];
    uint bx = base + ny * nz;
    lk[4] = links.v[bx];
    lk[5] = links.v[bx + 1u];
    lk[6] = links.v[bx + nz];
    lk[7] = links.v[bx + nz + 1u];
}

#endif
