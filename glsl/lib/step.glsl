// step.glsl — the per-step record shared by the training kernels: sample counters, and the
// "touched vertices" that let the optimiser visit only the vertices that received a gradient this
// step (method.md §2; svox2's sparse updates).
// Step record (`StepRecord`, common.glsl): the header `head` (StepHeader in src/abi/buffers.rs:
// touched count, the PlenoxelCounts of the stage-1 march, vertex count n), then `flags`: the
// touched flags of the n vertices (bit masks of parameter groups), then the touched list (n).
// The host zeroes head.count and head.stats each step; rmsprop_sparse clears the flags it visits.
// Include after a push block `pc` with member `step` (StepRecord). Rust twin: src/cpu/step.rs.
#ifndef STEP_GLSL
#define STEP_GLSL

#extension GL_KHR_shader_subgroup_arithmetic : require
#extension GL_KHR_shader_subgroup_basic : require

// The touched-flag bits TOUCH_ALL (stage 1's one group), TOUCH_DELTA, TOUCH_OPACITY, TOUCH_SH,
// TOUCH_SURFACE (stage 2 flags its three parameter groups apart): src/abi/consts.rs (abi.glsl).

// Set the bits m of vertex v's flag (m = 0: nothing); the first marker of the step appends v to
// the list.
void touch_mask(uint v, uint m) {
    if (m == 0u || (pc.step.flags[v] & m) == m) return;
    if (atomicOr(pc.step.flags[v], m) != 0u) return;
    uint i = atomicAdd(pc.step.head.count, 1u);
    pc.step.flags[pc.step.head.n + i] = v;
}

// Mark vertex v touched (every group).
void touch(uint v) {
    touch_mask(v, TOUCH_ALL);
}

// The record's counters += counts, reduced over the subgroup first: one atomic per subgroup and
// counter.
void add_stats(PlenoxelCounts counts) {
    PLENOXEL_COUNTS_SUBGROUP_ADD(pc.step.head.stats, counts);
}

#endif
