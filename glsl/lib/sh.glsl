// sh.glsl — real spherical harmonics of degree 2 (9 basis functions) on a unit direction, and the
// SH colour max(0, Σ_k Y_k·sh_k + 0.5) per channel (method.md §1; no sigmoid, no upper clamp).
// Coefficients per vertex: 27 floats [R0..R8, G0..G8, B0..B8]. Rust twin: src/math/sh.rs.
#ifndef SH_GLSL
#define SH_GLSL
#extension GL_EXT_control_flow_attributes : require

// SH_C0..SH_C4: src/abi/consts.rs (abi.glsl).

// The 9 basis values Y_0..Y_8 at the unit direction d (x, y, z).
void sh_basis(vec3 d, out float y[9]) {
    precise float xx = d.x * d.x;
    precise float yy = d.y * d.y;
    precise float zz = d.z * d.z;
    precise float y4 = SH_C2 * (d.x * d.y);
    precise float y5 = -SH_C2 * (d.y * d.z);
    precise float y6 = SH_C3 * ((2.0 * zz - xx) - yy);
    precise float y7 = -SH_C2 * (d.x * d.z);
    precise float y8 = SH_C4 * (xx - yy);
    y[0] = SH_C0;
    y[1] = -SH_C1 * d.y;
    y[2] = SH_C1 * d.z;
    y[3] = -SH_C1 * d.x;
    y[4] = y4;
    y[5] = y5;
    y[6] = y6;
    y[7] = y7;
    y[8] = y8;
}

// Σ_k y_k·c_k (FMA chain in k order).
float sh_dot(float y[9], float c[9]) {
    precise float acc = y[0] * c[0];
    for (int k = 1; k < 9; k++) {
        acc = fma(y[k], c[k], acc);
    }
    return acc;
}

// max(0, Σ_k y_k·c_k + 0.5): one colour channel.
float sh_channel(float y[9], float c[9]) {
    precise float v = sh_dot(y, c) + 0.5;
    return max(v, 0.0);
}

// S[k] = the 27 SH of vertex ROW in buffer BUF (F32Buf, 8-byte aligned), k < 27, moved as 13
// aligned 64-bit words (U64Buf, common.glsl) and one float — the first for odd ROW, the last for
// even ROW, as RMSPROP_UPDATE_SH27 — then placed with constant indices (S stays in registers).
#define SH27_LOAD(BUF, ROW, S) {                                                          \
    uint b_ = 27u * (ROW);                                                              \
    bool odd_ = (b_ & 1u) != 0u;                                                        \
    U64Buf w_ = U64Buf(uint64_t(BUF) + 4ul * uint64_t(odd_ ? b_ + 1u : b_));            \
    float one_ = BUF.v[odd_ ? b_ : b_ + 26u];                                           \
    vec2 pr_[13];                                                                       \
    [[unroll]] for (uint j_ = 0u; j_ < 13u; j_++) pr_[j_] = uintBitsToFloat(unpack32(w_.v[j_])); \
    [[unroll]] for (uint k_ = 0u; k_ < 27u; k_++) {                                     \
        float e_ = k_ == 26u ? one_ : ((k_ & 1u) == 0u ? pr_[k_ >> 1u].x : pr_[k_ >> 1u].y); \
        float o_ = k_ == 0u ? one_ : ((k_ & 1u) == 1u ? pr_[k_ >> 1u].x : pr_[(k_ >> 1u) - 1u].y); \
        S[k_] = odd_ ? o_ : e_;                                                         \
    }                                                                                   \
}

#endif
