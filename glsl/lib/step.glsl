// step.glsl — the per-step record shared by the training kernels: sample counters, and the
// "touched vertices" that let the optimiser visit only the vertices that received a gradient this
// step (method.md §2; svox2's sparse updates).
// Step buffer (u32) layout: [0] touched count, [1..5) counters (samples shaded, samples empty,
// samples skipped, gradient atomic adds), [5] vertex count n, [STEP_FLAGS, STEP_FLAGS + n) touched flags, then the touched list (n).
// The host zeroes [0, 5) each step; rmsprop_sparse clears the flags it visits.
// Include after a push block `pc` with member `step` (U32Buf). Rust twin: src/cpu/step.rs.
#ifndef STEP_GLSL
#define STEP_GLSL

#extension GL_KHR_shader_subgroup_arithmetic : require
#extension GL_KHR_shader_subgroup_basic : require

const uint STEP_COUNT = 0u;
const uint STEP_STATS = 1u;
const uint STEP_N = 5u;
const uint STEP_FLAGS = 8u;

// Mark vertex v touched (once per step: the first marker appends it to the list).
void touch(uint v) {
    if (pc.step.v[STEP_FLAGS + v] != 0u) return;
    if (atomicExchange(pc.step.v[STEP_FLAGS + v], 1u) != 0u) return;
    uint i = atomicAdd(pc.step.v[STEP_COUNT], 1u);
    pc.step.v[STEP_FLAGS + pc.step.v[STEP_N] + i] = v;
}

// The counters += (shaded, empty, skipped, atomic adds), reduced over the subgroup first: one
// atomic per subgroup and counter.
void add_stats(uvec4 counts) {
    uvec4 s = subgroupAdd(counts);
    if (subgroupElect()) {
        for (uint i = 0u; i < 4u; i++) atomicAdd(pc.step.v[STEP_STATS + i], s[i]);
    }
}

#endif
