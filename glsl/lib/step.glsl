// step.glsl — the per-step record shared by the training kernels: sample counters, and the
// "touched vertices" that let the optimiser visit only the vertices that received a gradient this
// step (method.md §2; svox2's sparse updates).
// Step buffer (u32) layout: [0] touched count, [1..5) counters (PlenoxelCounts: samples shaded,
// samples empty, samples skipped, gradient atomic adds), [5] vertex count n, [STEP_FLAGS, STEP_FLAGS + n) touched flags (bit masks of parameter groups), then
// the touched list (n).
// The host zeroes [0, 5) each step; rmsprop_sparse clears the flags it visits.
// Include after a push block `pc` with member `step` (U32Buf). Rust twin: src/cpu/step.rs.
#ifndef STEP_GLSL
#define STEP_GLSL

#extension GL_KHR_shader_subgroup_arithmetic : require
#extension GL_KHR_shader_subgroup_basic : require

// The layout indices STEP_COUNT, STEP_STATS, STEP_N, STEP_FLAGS and the touched-flag bits
// TOUCH_ALL (stage 1's one group), TOUCH_DELTA, TOUCH_OPACITY, TOUCH_SH, TOUCH_SURFACE (stage 2
// flags its three parameter groups apart): src/abi/consts.rs (abi.glsl).

// Set the bits m of vertex v's flag (m = 0: nothing); the first marker of the step appends v to
// the list.
void touch_mask(uint v, uint m) {
    if (m == 0u || (pc.step.v[STEP_FLAGS + v] & m) == m) return;
    if (atomicOr(pc.step.v[STEP_FLAGS + v], m) != 0u) return;
    uint i = atomicAdd(pc.step.v[STEP_COUNT], 1u);
    pc.step.v[STEP_FLAGS + pc.step.v[STEP_N] + i] = v;
}

// Mark vertex v touched (every group).
void touch(uint v) {
    touch_mask(v, TOUCH_ALL);
}

// The record's counters += counts, reduced over the subgroup first: one atomic per subgroup and
// counter.
void add_stats(PlenoxelCounts counts) {
    PLENOXEL_COUNTS_SUBGROUP_ADD(PlenoxelCountsBuf(uint64_t(pc.step) + 4ul * STEP_STATS), counts);
}

#endif
