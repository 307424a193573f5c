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

#endif
