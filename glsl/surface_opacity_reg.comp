#version 460
// surface_opacity_reg — gradient and value of the stage-2 opacity regulariser Lα (method.md §3.4):
// Lα = λ·Σ log σα over the rows r of a contiguous chunk of allocated vertices with σα_r > 0;
// ∂Lα/∂σα = λ/max(σα, 1e-8) where σα > 0, 0 otherwise. Nothing is flagged touched:
// surface_rmsprop's σα range pass updates σα on every row of the chunk.
// The chunk is rows (start + i) mod rows for i < min(count, rows): this kernel wraps, so the
// caller may draw start uniformly in [0, rows) (the 10 % chunk of the spec).
// Thread mapping: invocation i < S = ⌈min(count, rows)/16⌉ handles chunk rows i + k·S, k < 16
// (one owner per gradient element, no atomics).
// Inputs: opacity (raw σα per allocated vertex), rows, start, count, lambda.
// Outputs: grad += (plain read-modify-write) for each row with σα > 0;
// loss[0] += λ·Σ log σα (float atomic add, one per subgroup; the host zeroes it).
// CPU twin: `cpu::surface_opacity_reg::surface_opacity_reg`.
#include "common.glsl"
#extension GL_EXT_shader_atomic_float : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#extension GL_KHR_shader_subgroup_basic : require
layout(local_size_x = 256) in;

layout(push_constant, scalar) uniform Push {
    F32Buf opacity;
    F32Buf grad;
    F32Buf loss;
    uint rows;
    uint start;
    uint count;
    float lambda;
} pc;

// OPACITY_REG_ROWS rows per invocation (lavapipe's cost per invocation is larger than one row's
// work).

void main() {
    uint id = flat_id();
    uint len = min(pc.count, pc.rows);
    uint stride = (len + OPACITY_REG_ROWS - 1u) / OPACITY_REG_ROWS;
    float l = 0.0;
    if (id < stride) {
        for (uint k = 0u; k < OPACITY_REG_ROWS; k++) {
            uint i = id + k * stride;
            if (i >= len) break;
            uint r = (pc.start % pc.rows + i) % pc.rows;
            float a = pc.opacity.v[r];
            if (a > 0.0) {
                l += pc.lambda * log(a);
                precise float g = pc.grad.v[r] + pc.lambda / max(a, 1e-8);
                pc.grad.v[r] = g;
            }
        }
    }
    float s = subgroupAdd(l);
    if (subgroupElect() && s != 0.0) atomicAdd(pc.loss.v[0], s);
}
