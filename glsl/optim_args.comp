#version 460
// optim_args — turns the touched-vertex count of a step into the indirect dispatch arguments of
// rmsprop_sparse (64 invocations per workgroup; rows of DISPATCH_ROW_GROUPS as in dispatch_1d).
// Thread mapping: a single invocation. Input: the step buffer's touched count (touch.glsl).
// Output: args[0..3] = (gx, gy, 1). CPU twin: `cpu::optim_args::optim_args`.
#include "common.glsl"
layout(local_size_x = 1) in;

layout(push_constant, scalar) uniform Push {
    StepRecord step;
    U32Buf args;
} pc;

#include "step.glsl"

void main() {
    uint groups = (pc.step.head.count + 63u) / 64u;
    uint gx = min(groups, DISPATCH_ROW_GROUPS);
    pc.args.v[0] = gx;
    pc.args.v[1] = gx == 0u ? 0u : (groups + gx - 1u) / gx;
    pc.args.v[2] = 1u;
}
