#version 460
// sample_rays_sort — sorts a batch of sample_rays' keys ascending in runs of SAMPLE_SORT_RAYS
// keys (the last run may be shorter), the middle one of the three dispatches that draw a batch
// (gpu::TrainViewBuffers::record_sample; CPU twin: `cpu::sample_rays_sort`).
// Thread mapping: one workgroup of SIDE = SAMPLE_SORT_SIDE invocations per run, each holding SIDE
// of the run's keys in registers (past the batch: all-ones padding, which sorts last), sorted by
// a bitonic network whose compare-exchanges all run between registers of one invocation: in
// layout A invocation t's register q holds element t·SIDE + q of the network (its passes on the
// low log2(SIDE) element bits run there), in layout B element q·SIDE + t (the passes on the high
// bits); the keys change layout through shared memory, twice per merge stage that has high-bit
// passes (12 moves in all, where one key per invocation and pass would take 78 shared-memory
// round trips). A kernel of its own: sample_rays' other passes have no barrier, which spares
// them lavapipe's cost of a workgroup that has one.
// Inputs: src (n keys). Output: dst (n keys, sorted per run).
#extension GL_EXT_control_flow_attributes : require
#include "common.glsl"
layout(local_size_x = SAMPLE_SORT_SIDE) in;

layout(push_constant, scalar) uniform Push {
    U64Buf src;
    U64Buf dst;
    uint n;
} pc;

const uint SIDE = SAMPLE_SORT_SIDE;
// log2(SIDE): reg_pass has a case per register bit (the host checks SIDE = 64 at compile time).
const uint SIDE_BITS = 6u;

// A run between layouts, element e at slot(e) (the XOR keeps a layout-A access of the SIDE
// invocations off a single shared-memory bank on a GPU).
shared uint64_t s_keys[SAMPLE_SORT_RAYS];

// The invocation's keys.
uint64_t k[SIDE];

uint slot(uint e) {
    return e ^ (e / SIDE);
}

// One bitonic pass over the register pairs (q, q + JR) (JR = 2^register bit, a constant),
// register q holding element ELEM(q), in the merge stage of blocks of kk elements (ascending
// where element & kk is 0).
#define REG_PASS(JR, ELEM) \
    [[unroll]] for (uint q = 0u; q < SIDE; q++) { \
        if ((q & (JR)) == 0u) { \
            uint64_t x = k[q], y = k[q + (JR)]; \
            bool swap = (x > y) == ((ELEM(q) & kk) == 0u); \
            k[q] = swap ? y : x; \
            k[q + (JR)] = swap ? x : y; \
        } \
    }
#define ELEM_A(q) (t * SIDE + (q))
#define ELEM_B(q) ((q) * SIDE + t)

// The pass on register bit b: element bit b in layout A, SIDE_BITS + b in layout B.
void reg_pass(uint b, bool layout_b, uint kk, uint t) {
    if (layout_b) {
        switch (b) {
        case 0u: REG_PASS(1u, ELEM_B) break;
        case 1u: REG_PASS(2u, ELEM_B) break;
        case 2u: REG_PASS(4u, ELEM_B) break;
        case 3u: REG_PASS(8u, ELEM_B) break;
        case 4u: REG_PASS(16u, ELEM_B) break;
        default: REG_PASS(32u, ELEM_B) break;
        }
    } else {
        switch (b) {
        case 0u: REG_PASS(1u, ELEM_A) break;
        case 1u: REG_PASS(2u, ELEM_A) break;
        case 2u: REG_PASS(4u, ELEM_A) break;
        case 3u: REG_PASS(8u, ELEM_A) break;
        case 4u: REG_PASS(16u, ELEM_A) break;
        default: REG_PASS(32u, ELEM_A) break;
        }
    }
}

// Moves the keys to layout B (to_b) or back to A through shared memory. An invocation stores
// into the slots it loaded at the previous move (the same layout), which no other invocation
// reads, so one barrier, between store and load, suffices.
void to_layout(bool to_b, uint t) {
    [[unroll]] for (uint q = 0u; q < SIDE; q++) s_keys[slot(to_b ? ELEM_A(q) : ELEM_B(q))] = k[q];
    barrier();
    [[unroll]] for (uint q = 0u; q < SIDE; q++) k[q] = s_keys[slot(to_b ? ELEM_B(q) : ELEM_A(q))];
}

void main() {
    const uint t = gl_LocalInvocationID.x;
    const uint run = (flat_id() - t) / SIDE;
    // Workgroups past the last run (the dispatch grid's last row) leave as a whole.
    if (run > (pc.n - 1u) / SAMPLE_SORT_RAYS) return;
    const uint first = run * SAMPLE_SORT_RAYS;
    const uint count = min(SAMPLE_SORT_RAYS, pc.n - first);
    [[unroll]] for (uint q = 0u; q < SIDE; q++) {
        uint e = ELEM_A(q);
        k[q] = e < count ? pc.src.v[first + e] : ~0ul;
    }
    for (uint kk = 2u; kk <= SAMPLE_SORT_RAYS; kk <<= 1) {
        if (kk > SIDE) {
            to_layout(true, t);
            for (uint j = kk >> 1; j >= SIDE; j >>= 1) reg_pass(findLSB(j) - SIDE_BITS, true, kk, t);
            to_layout(false, t);
        }
        for (uint j = min(kk, SIDE) >> 1; j > 0u; j >>= 1) reg_pass(findLSB(j), false, kk, t);
    }
    [[unroll]] for (uint q = 0u; q < SIDE; q++) {
        uint e = ELEM_A(q);
        if (e < count) pc.dst.v[first + e] = k[q];
    }
}
