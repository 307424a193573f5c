#version 460
// surface_rmsprop — one RMSProp step of the stage-2 grid (method.md §3.5; the update is
// rmsprop.glsl's, as in rmsprop_sparse): r ← (r == 0 ? g² : β·r + (1 − β)·g²);
// θ ← θ − lr·g/(√r + ε); g ← 0. Parameter groups: δ (lr_delta), raw opacity σα (lr_opacity),
// the 27 SH (lr_sh). The δ range, rows (delta_start + i) mod rows for i < delta_len (≤ rows; 0:
// none), holds the rows the step's δ regularisers reach (Lδ's window; every row for a whole-grid
// Lδ) and the σα range (opacity_start, opacity_len) Lα's chunk: there the group is updated
// flagged or not (a row without a gradient only sees r decay). Passes:
// - range (range_pass = 1: δ, 2: σα): the range's rows in aligned pairs (2m, 2m + 1): the
//   count = min(⌈((start mod 2) + len)/2⌉, ⌈rows/2⌉) pairs m = (⌊start/2⌋ + j) mod ⌈rows/2⌉;
//   invocation i < ⌈count/16⌉ updates that group alone on pairs j = i + k·⌈count/16⌉ < count,
//   k < 16: both rows as one 64-bit word each when both are in the range (RMSPROP_UPDATE_PAIR),
//   else the one that is. (16 pairs per invocation: lavapipe's cost per invocation is larger than
//   one update's, docs/tuning.md. Pairs halve the memory operations.)
// - list (range_pass = 0): one invocation per entry of the touched list (indirect dispatch with
//   the arguments optim_args writes); vertex v updates the groups whose bits are set in its flag
//   (step.glsl TOUCH_*), δ and σα only outside their ranges, then its flag is cleared.
//   A group that received no gradient this step is left alone, its RMS state included (svox2's
//   sparse update, per group). The regularisers need not flag the rows of the ranges, which
//   keeps the list (one invocation each) short.
// SH through RMSPROP_UPDATE_SH27 (64-bit pairs: lavapipe moves memory one component at a time).
// Inputs/outputs: delta, opacity, sh, their gradients and RMS states; rows, the ranges; the step
// buffer (list pass: the list; its flags are cleared, the host resets the count). CPU twin: `cpu::surface_rmsprop` (both passes at once).
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
    StepRecord step;
    float lr_delta;
    float lr_opacity;
    float lr_sh;
    float beta;
    float eps;
    uint rows;
    uint delta_start;
    uint delta_len;
    uint opacity_start;
    uint opacity_len;
    uint range_pass;
} pc;

#include "rmsprop.glsl"

// Row pairs per invocation of the range pass: RMSPROP_RANGE_ROWS (src/abi/consts.rs).
#include "step.glsl"

void main() {
    uint i = flat_id();
    if (pc.range_pass != 0u) {
        bool delta = pc.range_pass == 1u;
        uint start = delta ? pc.delta_start : pc.opacity_start;
        uint len = delta ? pc.delta_len : pc.opacity_len;
        // The range's rows in aligned pairs (2m, 2m + 1), m cyclic over ⌈rows/2⌉ from start/2.
        uint pairs = (pc.rows + 1u) / 2u;
        uint count = min(((start & 1u) + len + 1u) / 2u, pairs);
        uint stride = (count + RMSPROP_RANGE_ROWS - 1u) / RMSPROP_RANGE_ROWS;
        if (i >= stride) return;
        F32Buf th = delta ? pc.delta : pc.opacity;
        F32Buf gr = delta ? pc.grad_delta : pc.grad_opacity;
        F32Buf st = delta ? pc.state_delta : pc.state_opacity;
        U64Buf th2 = U64Buf(uint64_t(th));
        U64Buf gr2 = U64Buf(uint64_t(gr));
        U64Buf st2 = U64Buf(uint64_t(st));
        float lr = delta ? pc.lr_delta : pc.lr_opacity;
        for (uint k = 0u; k < RMSPROP_RANGE_ROWS; k++) {
            uint j = i + k * stride;
            if (j >= count) break;
            uint m = range_row(start >> 1u, j, pairs);
            uint v = 2u * m;
            bool in0 = range_contains(start, len, pc.rows, v);
            bool in1 = v + 1u < pc.rows && range_contains(start, len, pc.rows, v + 1u);
            if (in0 && in1) {
                RMSPROP_UPDATE_PAIR(th2, gr2, st2, m, lr);
            } else if (in0) {
                RMSPROP_UPDATE(th, gr, st, v, lr);
            } else if (in1) {
                RMSPROP_UPDATE(th, gr, st, v + 1u, lr);
            }
        }
        return;
    }
    if (i >= pc.step.head.count) return;
    uint v = pc.step.flags[pc.step.head.n + i];
    uint m = pc.step.flags[v];
    if (range_contains(pc.delta_start, pc.delta_len, pc.rows, v)) m &= ~TOUCH_DELTA;
    if (range_contains(pc.opacity_start, pc.opacity_len, pc.rows, v)) m &= ~TOUCH_OPACITY;
    if ((m & TOUCH_DELTA) != 0u) RMSPROP_UPDATE(pc.delta, pc.grad_delta, pc.state_delta, v, pc.lr_delta);
    if ((m & TOUCH_OPACITY) != 0u) {
        RMSPROP_UPDATE(pc.opacity, pc.grad_opacity, pc.state_opacity, v, pc.lr_opacity);
    }
    if ((m & TOUCH_SH) != 0u) RMSPROP_UPDATE_SH27(pc.sh, pc.grad_sh, pc.state_sh, v, pc.lr_sh);
    pc.step.flags[v] = 0u;
}
