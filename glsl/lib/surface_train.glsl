// surface_train.glsl — the per-ray pieces of stage-2 training (glsl/surface_train.comp) that read
// no buffer: the record of a composited hit and its shading from one corner, the f′ guard,
// compositing from the records, the entropy LH and depth consistency Lc with their gradients, one
// step of the reverse recurrence, the gradients of a hit's σα and δ, and the per-corner gradient
// sums of a cell (method.md §3.2–3.4).
// Rust twin: src/math/surface_train.rs (same operations in the same order).
// Needs SURF_MAX_HITS and FPRIME_GUARD (abi.glsl, through common.glsl).
#ifndef SURFACE_TRAIN_GLSL
#define SURFACE_TRAIN_GLSL

#include "surface.glsl"

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

// Adds corner i's share to a hit's shading and its derivatives along the ray: trilinear weight w,
// its derivative dw along the ray, the corner's raw σα op, δ c and SH coefficients shv (27), SH
// basis y. h.raw starts at 0.5, h.draw, h.dsa and h.f1 at 0.
void surf_shade_corner(inout HitRec h, float w, float dw, float op, float c, float y[9],
                       float shv[27]) {
    precise float dsa = h.dsa + dw * op;
    h.dsa = dsa;
    precise float f1 = h.f1 + dw * c;
    h.f1 = f1;
    [[unroll]] for (uint ch = 0u; ch < 3u; ch++) {
        precise float v = 0.0;
        [[unroll]] for (uint k = 0u; k < 9u; k++) v += y[k] * shv[ch * 9u + k];
        precise float raw = h.raw[ch] + w * v;
        h.raw[ch] = raw;
        precise float draw = h.draw[ch] + dw * v;
        h.draw[ch] = draw;
    }
}

// The f′ guard: |f′(s)| ≤ FPRIME_GUARD·(max − min of the cell's δ c) gives δ no gradient.
bool surf_guard(float f1, float c[8]) {
    vec2 range = surf_cell_range(c);
    return abs(f1) <= FPRIME_GUARD * (range.y - range.x);
}

// Compositing from the nh records: the transmittance before each slot tr (the slots past nh copy
// tr[nh], so tr[SURF_MAX_HITS] is the ray's final one), the weights wj (0 past nh) and the colour
// before the background. Runs over all slots with a guard, unrolled, so that every index is a
// constant.
vec3 surf_composite(HitRec rec[SURF_MAX_HITS], uint nh, out float tr[SURF_MAX_HITS + 1u],
                    out float wj[SURF_MAX_HITS]) {
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
    return color;
}

// Entropy LH of the nh normalised weights wj (0 when lambda_h = 0 or Σw ≤ 1e-8), and
// e_j = ∂(λH·LH)/∂w_j (0 where w_j = 0 or LH is not formed).
float surf_entropy(float wj[SURF_MAX_HITS], uint nh, float lambda_h, out float e[SURF_MAX_HITS]) {
    [[unroll]] for (uint k = 0u; k < SURF_MAX_HITS; k++) e[k] = 0.0;
    precise float wsum = 0.0;
    [[unroll]] for (uint k = 0u; k < SURF_MAX_HITS; k++) {
        if (k < nh) wsum += wj[k];
    }
    precise float H = 0.0;
    if (lambda_h == 0.0 || !(wsum > 1e-8)) return H;
    [[unroll]] for (uint k = 0u; k < SURF_MAX_HITS; k++) {
        if (k < nh && wj[k] > 0.0) {
            precise float pk = wj[k] / wsum;
            H -= pk * log(pk);
        }
    }
    [[unroll]] for (uint k = 0u; k < SURF_MAX_HITS; k++) {
        if (k < nh && wj[k] > 0.0) {
            precise float ek = -lambda_h * (log(wj[k] / wsum) + H) / wsum;
            e[k] = ek;
        }
    }
    return H;
}

// Lc per structure (one, unless the truncation count restarts) over the nh records with weights
// wj: Σ |t_j − t_mode| with depths in scene units (× inv_len), the structure's mode = its first
// largest weight (0 when lambda_c = 0 or nh ≤ 1), and d_t_j = ∂(λc·Lc)/∂t_j; ∂/∂t_mode is summed
// apart per structure (the same additions in the same order). Structures are runs of records with
// one sid, so each pass below is one sweep over the slots.
float surf_consistency(HitRec rec[SURF_MAX_HITS], float wj[SURF_MAX_HITS], uint nh,
                       float lambda_c, float inv_len, out float d_t[SURF_MAX_HITS]) {
    [[unroll]] for (uint k = 0u; k < SURF_MAX_HITS; k++) d_t[k] = 0.0;
    precise float lc = 0.0;
    if (lambda_c == 0.0 || nh <= 1u) return lc;
    // Each slot's mode and the mode's depth: running forward over its run, then handed back from
    // the run's last slot.
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
    // The terms, and per run −Σ λ·sign over its other slots (left at each slot as the run's sum so
    // far, then handed back from the run's last slot to its mode).
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
    return lc;
}

// One step of the reverse recurrence at hit h (transmittance before it trk, weight wk, entropy
// gradient ek; dL/dC d_c): returns ∂L/∂α̃, sets ∂L/∂raw (ReLU-gated) and moves the colour s_c and
// entropy s_e seen from behind the hit to those seen from before it.
float surf_reverse_step(HitRec h, float trk, float wk, float ek, vec3 d_c, inout vec3 s_c,
                        inout float s_e, out vec3 d_raw) {
    float at = h.at;
    vec3 raw = h.raw;
    vec3 col = max(raw, vec3(0.0));
    precise float d_at = trk * (ek - s_e);
    [[unroll]] for (uint ch = 0u; ch < 3u; ch++) {
        precise float term = d_c[ch] * trk * (col[ch] - s_c[ch]);
        d_at += term;
    }
    precise vec3 dr = mix(vec3(0.0), d_c * wk, greaterThan(raw, vec3(0.0)));
    d_raw = dr;
    precise vec3 sc = at * col + (1.0 - at) * s_c;
    s_c = sc;
    precise float se = at * ek + (1.0 - at) * s_e;
    s_e = se;
    return d_at;
}

// ∂L/∂σα = ∂L/∂α̃·γ·e^{−σα} (σα > 0) into d_sa, and the δ scale: ∂L/∂δ_i = w_i·(returned value) =
// −w_i·(∂L/∂s)/f′(s), where ∂L/∂s collects opacity and colour moving with the hit point and the
// depth gradient dtk (Lc; × inv_len to scene units); 0 where the f′ guard holds or ∂L/∂s = 0.
float surf_hit_grads(HitRec h, float d_at, vec3 d_raw, float dtk, float inv_len,
                     out float d_sa) {
    float sa = h.sa;
    float ex = exp(-max(sa, 0.0));
    precise float g_sa = sa > 0.0 ? d_at * h.gam * ex : 0.0;
    d_sa = g_sa;
    precise float dl_ds = g_sa * h.dsa + dtk * inv_len;
    [[unroll]] for (uint ch = 0u; ch < 3u; ch++) dl_ds += d_raw[ch] * h.draw[ch];
    precise float dds = (h.guard || dl_ds == 0.0) ? 0.0 : -dl_ds / h.f1;
    return dds;
}

// Per-corner gradient sums of the hits of one cell (SH as 3 colour sums: Y is constant along a
// ray) and which corners and parameters received a non-zero term: bit i of nz_d / nz_a, bit
// 3i + ch of nz_c, set from single products (a sum's exact zero could depend on whether the
// compiler fused its additions, a product's cannot).
struct CornerSums {
    float d[8];
    float a[8];
    vec3 c[8];
    uint nz_d;
    uint nz_a;
    uint nz_c;
};

CornerSums corner_sums_zero() {
    CornerSums s;
    [[unroll]] for (uint i = 0u; i < 8u; i++) {
        s.d[i] = 0.0;
        s.a[i] = 0.0;
        s.c[i] = vec3(0.0);
    }
    s.nz_d = 0u;
    s.nz_a = 0u;
    s.nz_c = 0u;
    return s;
}

// Adds a hit's terms with trilinear weights wt: w_i·dds to δ, w_i·d_sa to σα, w_i·d_raw to the
// colour sums.
void surf_sums_add(inout CornerSums s, float wt[8], float dds, float d_sa, vec3 d_raw) {
    [[unroll]] for (uint i = 0u; i < 8u; i++) {
        precise float td = wt[i] * dds;
        precise float ta = wt[i] * d_sa;
        precise vec3 tc = wt[i] * d_raw;
        precise float gd = s.d[i] + td;
        s.d[i] = gd;
        precise float ga = s.a[i] + ta;
        s.a[i] = ga;
        precise vec3 gc = s.c[i] + tc;
        s.c[i] = gc;
        s.nz_d |= uint(td != 0.0) << i;
        s.nz_a |= uint(ta != 0.0) << i;
        s.nz_c |= (uint(tc.x != 0.0) | (uint(tc.y != 0.0) << 1u) | (uint(tc.z != 0.0) << 2u)) << (3u * i);
    }
}

#endif
