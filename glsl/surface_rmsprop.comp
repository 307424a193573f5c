#version 460
// surface_rmsprop — one RMSProp step of the stage-2 grid (method.md §3.5; the update is
// rmsprop.glsl's, as in rmsprop_sparse): r ← (r == 0 ? g² : β·r + (1 − β)·g²);
// θ ← θ − lr·g/(√r + ε); g ← 0. Parameter groups: δ (lr_delta), raw opacity σα (lr_opacity),
// the 27 SH (lr_sh). Two modes:
// - list (dense_rows = 0): one invocation per entry of the touched list (indirect dispatch with
//   the arguments optim_args writes); vertex v updates the groups whose bits are set both in its
//   flag and in `groups` (step.glsl TOUCH_*), then its flag is cleared. A group that received no
//   gradient this step is left alone, its RMS state included (svox2's sparse update, per group).
// - dense (dense_rows = n): invocation i < ⌈n/16⌉ updates δ alone of the rows i + k·⌈n/16⌉,
//   k < 16, for steps where a regulariser gives every vertex a δ gradient (Lδ); the list pass
//   then runs without the δ bit. (16 rows per invocation: lavapipe's cost per invocation is
//   larger than one update's; one row each took 3× as long, measured.)
// SH through RMSPROP_UPDATE_SH27 (64-bit pairs; measured: the list pass 6.3 → 4.7 ms per bench
// surface step).
// Inputs/outputs: delta, opacity, sh, their gradients and RMS states; the step buffer (list mode:
// the list; its flags are cleared, the host resets the count). CPU twin:
// cpu::surface_rmsprop_sparse (both modes at once).
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
    uint groups;
    uint dense_rows;
} pc;

#include "rmsprop.glsl"

// Rows per invocation of the dense pass.
const uint DENSE_ROWS = 16u;
#include "step.glsl"

void main() {
    uint i = flat_id();
    if (pc.dense_rows != 0u) {
        uint stride = (pc.dense_rows + DENSE_ROWS - 1u) / DENSE_ROWS;
        if (i >= stride) return;
        for (uint k = 0u; k < DENSE_ROWS; k++) {
            uint v = i + k * stride;
            if (v < pc.dense_rows) RMSPROP_UPDATE(pc.delta, pc.grad_delta, pc.state_delta, v, pc.lr_delta);
        }
        return;
    }
    if (i >= pc.step.v[STEP_COUNT]) return;
    uint v = pc.step.v[STEP_FLAGS + pc.step.v[STEP_N] + i];
    uint m = pc.step.v[STEP_FLAGS + v] & pc.groups;
    if ((m & TOUCH_DELTA) != 0u) RMSPROP_UPDATE(pc.delta, pc.grad_delta, pc.state_delta, v, pc.lr_delta);
    if ((m & TOUCH_OPACITY) != 0u) {
        RMSPROP_UPDATE(pc.opacity, pc.grad_opacity, pc.state_opacity, v, pc.lr_opacity);
    }
    if ((m & TOUCH_SH) != 0u) RMSPROP_UPDATE_SH27(pc.sh, pc.grad_sh, pc.state_sh, v, pc.lr_sh);
    pc.step.v[STEP_FLAGS + v] = 0u;
}
