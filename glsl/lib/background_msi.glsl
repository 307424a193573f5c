// background_msi.glsl — the background of a 360° capture: concentric spheres around the grid
// box (src/abi/buffers.rs `BackgroundSpheres`). A ray meets every sphere it leaves, nearest
// first; the exit point, seen from the centre, indexes the sphere's octahedral map (bilinear,
// its border folded where the octahedron's edges meet), whose texel (σ, r, g, b) gives
// α = 1 − exp(−max(σ, 0)), c = max(rgb, 0). B = Σ_l T_l α_l c_l + T_L·rgb.
// bg_msi_backward exists where the kernel defines BG_MSI_BACKWARD (and enables
// GL_EXT_shader_atomic_float) before including this file.
// Rust twin: math::background_msi (exit_point, octahedral_uv, taps, composite, backward).
#ifndef BACKGROUND_MSI_GLSL
#define BACKGROUND_MSI_GLSL

const uint BG_TEXEL = 4u;

// Radius of sphere l.
float bg_msi_radius(BackgroundSpheres s, uint l) {
    precise float inv = s.inv_r0 - float(l) * s.inv_step;
    return 1.0 / inv;
}

// Where the ray from oc (origin − centre) along unit d leaves the sphere of radius r, from the
// centre: h + √(r² − |h|²)·d, h the line's point nearest the centre. false where the line
// misses or touches the sphere, or leaves it behind the origin.
bool bg_msi_exit(vec3 oc, vec3 d, float r, out vec3 p) {
    // Sums of products written out (not dot(), which a driver may fuse): the twin's order, and
    // the branches below take the same side on every device.
    precise float b = oc.x * d.x + oc.y * d.y + oc.z * d.z;
    precise vec3 h = oc - b * d;
    precise float disc = r * r - (h.x * h.x + h.y * h.y + h.z * h.z);
    p = vec3(0.0);
    if (!(disc > 0.0)) return false;
    float s = sqrt(disc);
    if (!(s > b)) return false;
    precise vec3 q = h + s * d;
    p = q;
    return true;
}

// Texel coordinates in [−½, size − ½]² of direction p in the octahedral map.
vec2 bg_msi_uv(vec3 p, uint size) {
    precise float s = abs(p.x) + abs(p.y) + abs(p.z);
    float a = p.x / s;
    float b = p.y / s;
    if (p.z < 0.0) {
        float fa = 1.0 - abs(b);
        float fb = 1.0 - abs(a);
        a = p.x >= 0.0 ? fa : -fa;
        b = p.y >= 0.0 ? fb : -fb;
    }
    float n = float(size);
    precise vec2 uv = (vec2(a, b) + 1.0) * 0.5 * n - 0.5;
    return uv;
}

// One axis of bg_msi_fold: a coordinate a one past the border (−1 or n) comes back to the
// border, and the other coordinate b mirrors about the map's middle.
ivec2 bg_msi_fold_axis(int a, int b, int n) {
    return (a < 0 || a >= n) ? ivec2(clamp(a, 0, n - 1), n - 1 - b) : ivec2(a, b);
}

// The texel a tap one past the border reads: the border's halves mirrored about their midpoints.
uint bg_msi_fold(int i, int j, int n) {
    ivec2 ij = bg_msi_fold_axis(i, j, n);
    ivec2 ji = bg_msi_fold_axis(ij.y, ij.x, n);
    return uint(ji.x * n + ji.y);
}

// Where a ray reads sphere l: the first value of each of its four texels in the table, their
// bilinear weights.
struct BgTaps {
    uint at[4];
    float w[4];
};

bool bg_msi_taps(BackgroundSpheres s, uint l, vec3 oc, vec3 d, out BgTaps t) {
    vec3 p;
    if (!bg_msi_exit(oc, d, bg_msi_radius(s, l), p)) return false;
    float n = float(s.size);
    vec2 uv = clamp(bg_msi_uv(p, s.size), vec2(-0.5), vec2(n - 0.5));
    vec2 f0 = floor(uv);
    vec2 f = uv - f0;
    int i = int(f0.x), j = int(f0.y), sz = int(s.size);
    uint base = l * s.size * s.size;
    t.at[0] = (base + bg_msi_fold(i, j, sz)) * BG_TEXEL;
    t.at[1] = (base + bg_msi_fold(i + 1, j, sz)) * BG_TEXEL;
    t.at[2] = (base + bg_msi_fold(i, j + 1, sz)) * BG_TEXEL;
    t.at[3] = (base + bg_msi_fold(i + 1, j + 1, sz)) * BG_TEXEL;
    precise float w0 = (1.0 - f.x) * (1.0 - f.y);
    precise float w1 = f.x * (1.0 - f.y);
    precise float w2 = (1.0 - f.x) * f.y;
    precise float w3 = f.x * f.y;
    t.w[0] = w0;
    t.w[1] = w1;
    t.w[2] = w2;
    t.w[3] = w3;
    return true;
}

// The interpolated (σ, r, g, b) at the taps, summed in tap order as the twin.
vec4 bg_msi_value(F32Buf table, BgTaps t) {
    precise vec4 v = vec4(0.0);
    for (int k = 0; k < 4; k++) {
        vec4 x = vec4(table.v[t.at[k]], table.v[t.at[k] + 1u], table.v[t.at[k] + 2u],
                      table.v[t.at[k] + 3u]);
        precise vec4 acc = v + t.w[k] * x;
        v = acc;
    }
    return v;
}

float bg_msi_alpha(float sigma) {
    return 1.0 - exp(-max(sigma, 0.0));
}

// The spheres the ray (o, unit d) leaves, nearest first: returns B (in front of rgb) and T_L in
// `t_out`; with `back` (only where BG_MSI_BACKWARD is defined) adds dL/d(texel values) of the
// ray given dL/dB = g and its B = total to s.grad (float atomics): per sphere
// dL/dσ = Σ_ch g·(T_{l+1} c_l − (B − B_≤l)) where σ > 0, dL/dc = g·T_l α_l where the colour is
// positive, spread over the taps by their weights. One loop for both, as the twin's `march`.
vec3 bg_msi_march(BackgroundSpheres s, vec3 o, vec3 d, vec3 rgb, bool back, vec3 total, vec3 g,
                  out float t_out) {
    F32Buf table = F32Buf(packUint2x32(s.table));
    precise vec3 oc = o - s.centre;
    vec3 color = vec3(0.0);
    float T = 1.0;
    for (uint l = 0u; l < s.layers; l++) {
        BgTaps tp;
        if (!bg_msi_taps(s, l, oc, d, tp)) continue;
        vec4 v = bg_msi_value(table, tp);
        float alpha = bg_msi_alpha(v.x);
        vec3 c = max(v.yzw, vec3(0.0));
        precise float wt = T * alpha;
        precise vec3 acc = color + wt * c;
        color = acc;
        precise float tn = T * (1.0 - alpha);
#ifdef BG_MSI_BACKWARD
        if (back) {
            F32Buf grad = F32Buf(packUint2x32(s.grad));
            vec4 dv = vec4(0.0);
            if (v.x > 0.0) {
                precise vec3 e = g * (tn * c - (total - color));
                precise float ds = e.x + e.y + e.z;
                dv.x = ds;
            }
            for (int ch = 0; ch < 3; ch++) {
                if (v[1 + ch] > 0.0) dv[1 + ch] = g[ch] * wt;
            }
            for (int k = 0; k < 4; k++) {
                for (int j = 0; j < 4; j++) {
                    if (dv[j] != 0.0) atomicAdd(grad.v[tp.at[k] + uint(j)], tp.w[k] * dv[j]);
                }
            }
        }
#endif
        T = tn;
    }
    t_out = T;
    precise vec3 outc = color + T * rgb;
    return outc;
}

// The background colour of the ray (o, unit d) in front of rgb, and T_L in `t_out`.
vec3 bg_msi_composite(BackgroundSpheres s, vec3 o, vec3 d, vec3 rgb, out float t_out) {
    return bg_msi_march(s, o, d, rgb, false, vec3(0.0), vec3(0.0), t_out);
}

#ifdef BG_MSI_BACKWARD
// dL/d(texel values) of the ray given dL/dB = g and total = B (bg_msi_march).
void bg_msi_backward(BackgroundSpheres s, vec3 o, vec3 d, vec3 total, vec3 g) {
    float t;
    bg_msi_march(s, o, d, vec3(0.0), true, total, g, t);
}
#endif

#endif
