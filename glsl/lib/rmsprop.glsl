// rmsprop.glsl — the RMSProp update of one scalar (method.md §2), as a macro (buffer references
// passed to GLSL functions become Function-storage pointers, which glslang emits as invalid
// SPIR-V). Include after a push block `pc` with members beta and eps.
// Rust twin: src/cpu/rmsprop.rs (`rmsprop_one`).
#ifndef RMSPROP_GLSL
#define RMSPROP_GLSL

#define RMSPROP_UPDATE(PARAM, GRAD, STATE, I, LR) {                                   \
    float g_ = GRAD.v[I];                                                               \
    float r_ = STATE.v[I];                                                              \
    precise float g2_ = g_ * g_;                                                        \
    precise float rn_ = r_ == 0.0 ? g2_ : pc.beta * r_ + (1.0 - pc.beta) * g2_;         \
    precise float step_ = (LR) * g_ / (sqrt(rn_) + pc.eps);                             \
    STATE.v[I] = rn_;                                                                   \
    PARAM.v[I] = PARAM.v[I] - step_;                                                    \
    GRAD.v[I] = 0.0;                                                                    \
}

// RMSPROP_UPDATE on the two floats of 64-bit word K (U64Buf, common.glsl) of PARAM, GRAD and STATE
// (U64Buf views of the same layout): the same operations, componentwise, with half the memory
// operations (lavapipe moves memory one component at a time).
#define RMSPROP_UPDATE_PAIR(TH, GR, ST, K, LR) {                                        \
    vec2 g_ = uintBitsToFloat(unpack32(GR.v[K]));                                       \
    vec2 r_ = uintBitsToFloat(unpack32(ST.v[K]));                                       \
    vec2 t_ = uintBitsToFloat(unpack32(TH.v[K]));                                       \
    precise vec2 g2_ = g_ * g_;                                                         \
    precise vec2 rn_ = mix(pc.beta * r_ + (1.0 - pc.beta) * g2_, g2_, equal(r_, vec2(0.0))); \
    precise vec2 step_ = (LR) * g_ / (sqrt(rn_) + pc.eps);                              \
    precise vec2 tn_ = t_ - step_;                                                      \
    ST.v[K] = pack64(floatBitsToUint(rn_));                                             \
    TH.v[K] = pack64(floatBitsToUint(tn_));                                             \
    GR.v[K] = 0ul;                                                                      \
}

// The update of the 27 SH of vertex V (floats 27V … 27V + 26), as 13 aligned 64-bit words
// (RMSPROP_UPDATE_PAIR) and one float (the first for odd V, the last for even V). Needs the
// buffers 8-byte aligned.
#define RMSPROP_UPDATE_SH27(PARAM, GRAD, STATE, V, LR) {                                  \
    uint b_ = 27u * (V);                                                                \
    uint p0_ = (b_ & 1u) != 0u ? b_ + 1u : b_;                                          \
    RMSPROP_UPDATE(PARAM, GRAD, STATE, (b_ & 1u) != 0u ? b_ : b_ + 26u, LR);            \
    U64Buf th_ = U64Buf(uint64_t(PARAM) + 4ul * uint64_t(p0_));                         \
    U64Buf gr_ = U64Buf(uint64_t(GRAD) + 4ul * uint64_t(p0_));                          \
    U64Buf st_ = U64Buf(uint64_t(STATE) + 4ul * uint64_t(p0_));                         \
    for (uint k_ = 0u; k_ < 13u; k_++) RMSPROP_UPDATE_PAIR(th_, gr_, st_, k_, LR);      \
}

#endif
