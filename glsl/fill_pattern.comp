#version 460
// fill_pattern — writes a hash of the element index into a u32 buffer of any size.
// Thread mapping: one invocation per element (flat 1-D index over a 2-D grid).
// Inputs: `n` elements, `seed`. Output: `dst[i] = hash(i ^ seed)`.
// Exists to prove that buffers above maxStorageBufferRange (128 MiB on lavapipe) work through
// device addresses; CPU twin: `cpu::fill_pattern`.
#include "common.glsl"
layout(local_size_x = 256) in;

layout(push_constant, scalar) uniform Push {
    U32Buf dst;
    uint n;
    uint seed;
} pc;

uint hash_u32(uint x) {
    x ^= x >> 16; x *= 0x7feb352du;
    x ^= x >> 15; x *= 0x846ca68bu;
    x ^= x >> 16;
    return x;
}

void main() {
    uint i = flat_id();
    if (i >= pc.n) return;
    pc.dst.v[i] = hash_u32(i ^ pc.seed);
}
