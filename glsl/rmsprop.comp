#version 460
// rmsprop — RMSProp step for one parameter array, applied only where the gradient is non-zero
// ("touched"), and the gradient accumulator cleared for the next step (method.md §2):
// r ← (r == 0 ? g² : β·r + (1 − β)·g²); θ ← θ − lr·g/(√r + ε); g ← 0.
// Thread mapping: one invocation per scalar parameter.
// Inputs/outputs: param, grad, state (r), all n floats; lr, beta, eps.
// CPU twin: cpu::rmsprop.
#include "common.glsl"
layout(local_size_x = 256) in;

layout(push_constant, scalar) uniform Push {
    F32Buf param;
    F32Buf grad;
    F32Buf state;
    uint n;
    float lr;
    float beta;
    float eps;
} pc;

void main() {
    uint i = flat_id();
    if (i >= pc.n) return;
    float g = pc.grad.v[i];
    if (g == 0.0) return;
    float r = pc.state.v[i];
    precise float g2 = g * g;
    precise float rn = r == 0.0 ? g2 : pc.beta * r + (1.0 - pc.beta) * g2;
    precise float step = pc.lr * g / (sqrt(rn) + pc.eps);
    pc.state.v[i] = rn;
    pc.param.v[i] = pc.param.v[i] - step;
    pc.grad.v[i] = 0.0;
}
