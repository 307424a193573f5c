#version 460
// surface_rmsprop — one RMSProp step of the stage-2 grid for the vertices touched this step (by
// the surface training and regulariser kernels), for its three parameter groups at once: δ
// (lr_delta), raw opacity σα (lr_opacity) and the 27 SH (lr_sh); then clears their gradients
// and their touched flag (method.md §3.5; the update is rmsprop.glsl's, as in rmsprop_sparse):
// r ← (r == 0 ? g² : β·r + (1 − β)·g²); θ ← θ − lr·g/(√r + ε); g ← 0.
// Thread mapping: one invocation per entry of the touched list (indirect dispatch with the
// arguments optim_args writes). Inputs/outputs: delta, opacity, sh, their gradients and RMS
// states; the step buffer (step.glsl) gives the list and has each visited flag cleared (the
// host resets the count). CPU twin: cpu::surface_rmsprop_sparse.
#include "common.glsl"
layout(local_size_x = 64) in;

layout(push_constant, scalar) uniform Push {
    F32Buf delta;
    F32Buf opacity;
    F32Buf sh;
    F32Buf grad_delta;
    F32Buf grad_opacity;
    F32Buf grad_sh;
    F32Buf state_delta;
    F32Buf state_opacity;
    F32Buf state_sh;
    U32Buf step;
    float lr_delta;
    float lr_opacity;
    float lr_sh;
    float beta;
    float eps;
} pc;

#include "rmsprop.glsl"
#include "step.glsl"

void main() {
    uint i = flat_id();
    if (i >= pc.step.v[STEP_COUNT]) return;
    uint v = pc.step.v[STEP_FLAGS + pc.step.v[STEP_N] + i];
    RMSPROP_UPDATE(pc.delta, pc.grad_delta, pc.state_delta, v, pc.lr_delta);
    RMSPROP_UPDATE(pc.opacity, pc.grad_opacity, pc.state_opacity, v, pc.lr_opacity);
    for (uint k = 0u; k < 27u; k++) {
        RMSPROP_UPDATE(pc.sh, pc.grad_sh, pc.state_sh, v * 27u + k, pc.lr_sh);
    }
    pc.step.v[STEP_FLAGS + v] = 0u;
}
