#version 460
// surface_rmsprop — one RMSProp step of the stage-2 grid (method.md §3.5; the update is
// rmsprop.glsl's, as in rmsprop_sparse): r ← (r == 0 ? g² : β·r + (1 − β)·g²);
// θ ← θ − lr·g/(√r + ε); g ← 0. Parameter groups: δ (lr_delta), raw opacity σα (lr_opacity),
// the 27 SH (lr_sh). The δ range is the rows (range_start + i) mod rows, i < range_len (≤ rows;
// 0: none): those the step's δ regularisers reach (Lδ's window; every row for a whole-grid Lδ),
// whose δ is updated flagged or not (a row there without a gradient only sees r decay). Two
// passes:
// - range (range_pass = 1): invocation i < ⌈len/16⌉ updates δ alone of the range's rows
//   i + k·⌈len/16⌉ < len, k < 16. (16 rows per invocation: lavapipe's cost per invocation is
//   larger than one update's; one row each took 3× as long, measured.)
// - list (range_pass = 0): one invocation per entry of the touched list (indirect dispatch with
//   the arguments optim_args writes); vertex v updates the groups whose bits are set in its flag
//   (step.glsl TOUCH_*), δ only outside the range, then its flag is cleared.
//   A group that received no gradient this step is left alone, its RMS state included (svox2's
//   sparse update, per group). The regularisers need not flag the rows of the range, which keeps
//   the list (one invocation each) short.
// SH through RMSPROP_UPDATE_SH27 (64-bit pairs; measured: the list pass 6.3 → 4.7 ms per bench
// surface step).
// Inputs/outputs: delta, opacity, sh, their gradients and RMS states; rows, the δ range; the step
// buffer (list pass: the list; its flags are cleared, the host resets the count). CPU twin:
// cpu::surface_rmsprop_sparse (both passes at once).
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
    uint rows;
    uint range_start;
    uint range_len;
    uint range_pass;
} pc;

#include "rmsprop.glsl"

// Rows per invocation of the range pass.
const uint RANGE_ROWS = 16u;
#include "step.glsl"

// Whether row v is in the δ range.
bool in_range(uint v) {
    return (v >= pc.range_start ? v - pc.range_start : v + (pc.rows - pc.range_start)) < pc.range_len;
}

void main() {
    uint i = flat_id();
    if (pc.range_pass != 0u) {
        uint stride = (pc.range_len + RANGE_ROWS - 1u) / RANGE_ROWS;
        if (i >= stride) return;
        for (uint k = 0u; k < RANGE_ROWS; k++) {
            uint j = i + k * stride;
            if (j >= pc.range_len) break;
            uint v = pc.range_start + j;
            if (v >= pc.rows) v -= pc.rows;
            RMSPROP_UPDATE(pc.delta, pc.grad_delta, pc.state_delta, v, pc.lr_delta);
        }
        return;
    }
    if (i >= pc.step.v[STEP_COUNT]) return;
    uint v = pc.step.v[STEP_FLAGS + pc.step.v[STEP_N] + i];
    uint m = pc.step.v[STEP_FLAGS + v];
    if (in_range(v)) m &= ~TOUCH_DELTA;
    if ((m & TOUCH_DELTA) != 0u) RMSPROP_UPDATE(pc.delta, pc.grad_delta, pc.state_delta, v, pc.lr_delta);
    if ((m & TOUCH_OPACITY) != 0u) {
        RMSPROP_UPDATE(pc.opacity, pc.grad_opacity, pc.state_opacity, v, pc.lr_opacity);
    }
    if ((m & TOUCH_SH) != 0u) RMSPROP_UPDATE_SH27(pc.sh, pc.grad_sh, pc.state_sh, v, pc.lr_sh);
    pc.step.v[STEP_FLAGS + v] = 0u;
}
