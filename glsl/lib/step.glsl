// step.glsl — the per-step record shared by the training kernels: sample counters, and the
// "touched vertices" that let the optimiser visit only the vertices that received a gradient this
// step (method.md §2; svox2's sparse updates).
// Step buffer (u32) layout: [0] touched count, [1..4) sample counters (shaded, empty, skipped),
// [4] vertex count n, [STEP_FLAGS, STEP_FLAGS + n) touched flags, then the touched list (n).
// The host zeroes [0, 4) each step; rmsprop_sparse clears the flags it visits.
// Include after a push block `pc` with member `step` (U32Buf). Rust twin: src/cpu/step.rs.
#ifndef STEP_GLSL
#define STEP_GLSL

#extension GL_KHR_shader_subgroup_arithmetic : require
#extension GL_KHR_shader_subgroup_basic : require

const uint STEP_COUNT = 0u;
const uint STEP_STATS = 1u;
const uint STEP_N = 4u;
const uint STEP_FLAGS = 8u;

// Mark vertex v touched (once per step: the first marker appends it to the list).
void touch(uint v) {
    if (pc.step.v[STEP_FLAGS + v] != 0u) return;
    if (atomicExchange(pc.step.v[STEP_FLAGS + v], 1u) != 0u) return;
    uint i = atomicAdd(pc.step.v[STEP_COUNT], 1u);
    pc.step.v[STEP_FLAGS + pc.step.v[STEP_N] + i] = v;
}

// The sample counters += (shaded, empty, skipped), reduced over the subgroup first: one atomic per
// subgroup and counter.
void add_stats(uvec3 counts) {
    uvec3 s = subgroupAdd(counts);
    if (subgroupElect()) {
        atomicAdd(pc.step.v[STEP_STATS], s.x);
        atomicAdd(pc.step.v[STEP_STATS + 1u], s.y);
        atomicAdd(pc.step.v[STEP_STATS + 2u], s.z);
    }
}

#endif
