#version 460
// rmsprop_sparse — one RMSProp step for the vertices touched this step (those the training and
// regulariser kernels listed), for σ and its 27 SH coefficients at once, then clears their
// gradients and their touched flag (method.md §2: only touched vertices update):
// r ← (r == 0 ? g² : β·r + (1 − β)·g²); θ ← θ − lr·g/(√r + ε); g ← 0.
// Thread mapping: one invocation per entry of the touched list (indirect dispatch from
// optim_args). Inputs/outputs: density, sh and their gradients and RMS states; the step buffer
// (step.glsl) gives the list and has each visited flag cleared. SH through RMSPROP_UPDATE_SH27
// (64-bit pairs).
// CPU twin: `cpu::rmsprop_sparse`.
#include "common.glsl"
layout(local_size_x = 64) in;

layout(push_constant, scalar) uniform Push {
    F32Buf density;
    F32Buf sh;
    F32Buf grad_density;
    F32Buf grad_sh;
    F32Buf state_density;
    F32Buf state_sh;
    StepRecord step;
    float lr_sigma;
    float lr_sh;
    float beta;
    float eps;
} pc;

#include "rmsprop.glsl"
#include "step.glsl"

void main() {
    uint i = flat_id();
    if (i >= pc.step.head.count) return;
    uint v = pc.step.flags[pc.step.head.n + i];
    RMSPROP_UPDATE(pc.density, pc.grad_density, pc.state_density, v, pc.lr_sigma);
    RMSPROP_UPDATE_SH27(pc.sh, pc.grad_sh, pc.state_sh, v, pc.lr_sh);
    pc.step.flags[v] = 0u;
}
