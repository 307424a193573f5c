#version 460
// loss_sum — the sums over a batch's rays of the first `fields` (≤ LOSS_SUM_FIELDS) floats of
// each ray's loss record (stage 1: the squared error; stage 2: RayLoss's squared error, entropy
// and consistency), written as `fields` floats at `dst`: a step's loss stays on the device (in a
// readback slot the host reads every K steps) instead of coming back ray by ray.
// Thread mapping: one workgroup of LOSS_SUM_THREADS invocations; invocation t adds records t,
// t + LOSS_SUM_THREADS, t + 2·LOSS_SUM_THREADS, … in that order, then a tree over shared memory
// (s[t] += s[t + h] for h = LOSS_SUM_THREADS/2, …, 1) gives the totals: a fixed order, which
// the twin follows, so the sums agree bit for bit. A NaN or Inf in any record reaches the sum.
// CPU twin: `cpu::loss_sum`.
#include "common.glsl"
layout(local_size_x = LOSS_SUM_THREADS) in;

layout(push_constant, scalar) uniform Push {
    F32Buf src;
    F32Buf dst;
    uint n;
    // Floats per record, and the leading ones summed.
    uint stride;
    uint fields;
} pc;

shared float s_sum[LOSS_SUM_THREADS * LOSS_SUM_FIELDS];

void main() {
    const uint t = gl_LocalInvocationID.x;
    const uint fields = min(pc.fields, LOSS_SUM_FIELDS);
    float acc[LOSS_SUM_FIELDS];
    for (uint f = 0u; f < LOSS_SUM_FIELDS; f++) acc[f] = 0.0;
    for (uint r = t; r < pc.n; r += LOSS_SUM_THREADS) {
        for (uint f = 0u; f < fields; f++) acc[f] += pc.src.v[r * pc.stride + f];
    }
    for (uint f = 0u; f < LOSS_SUM_FIELDS; f++) s_sum[t * LOSS_SUM_FIELDS + f] = acc[f];
    barrier();
    for (uint h = LOSS_SUM_THREADS / 2u; h > 0u; h >>= 1) {
        if (t < h) {
            for (uint f = 0u; f < LOSS_SUM_FIELDS; f++) {
                s_sum[t * LOSS_SUM_FIELDS + f] += s_sum[(t + h) * LOSS_SUM_FIELDS + f];
            }
        }
        barrier();
    }
    if (t < fields) pc.dst.v[t] = s_sum[t];
}
