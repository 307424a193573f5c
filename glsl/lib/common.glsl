// Shared kernel prelude: extensions, buffer-reference types and the flat thread index.
// Included first by every kernel. Buffers arrive as device addresses in the push-constant block.
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_buffer_reference2 : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_EXT_scalar_block_layout : require
// Constants and buffer structs shared with the host, generated from src/abi/ by build.rs.
#include "abi.glsl"

layout(buffer_reference, scalar, buffer_reference_align = 4) buffer F32Buf { float v[]; };
layout(buffer_reference, scalar, buffer_reference_align = 4) buffer U32Buf { uint v[]; };
layout(buffer_reference, scalar, buffer_reference_align = 4) buffer I32Buf { int v[]; };
// 64-bit words of an 8-byte aligned buffer: lavapipe loads and stores memory one component at a
// time, so moving floats in pairs halves the memory operations (SH27_LOAD, RMSPROP_UPDATE_SH27).
layout(buffer_reference, scalar, buffer_reference_align = 8) buffer U64Buf { uint64_t v[]; };
// The step record (step.glsl): its header (StepHeader, src/abi/buffers.rs), then the touched
// flags of the head.n vertices, then the touched list (head.count entries used): flags[n + i].
layout(buffer_reference, scalar, buffer_reference_align = 4) buffer StepRecord {
    StepHeader head;
    uint flags[];
};

// Flat invocation index for 1-D work split over a 2-D dispatch grid (each dimension is limited to
// 65535 workgroups); the host side is `gpu::Batch::dispatch_1d`, which fills rows of exactly
// DISPATCH_ROW_GROUPS workgroups whenever it needs more than one row. A macro, not a function:
// glslang fixes gl_WorkGroupSize where a function body is compiled, and this file is included
// before the kernel's `layout(local_size_x = …)`, where it would still read 1.
#define flat_id() (gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * (DISPATCH_ROW_GROUPS * gl_WorkGroupSize.x))

// Cyclic row ranges (Rust twin: abi::step::RowRange): the rows (start + i) mod n for i < len,
// start < n, len ≤ n.
// Row i (< n) of the range starting at `start`.
uint range_row(uint start, uint i, uint n) {
    uint k = start + i;
    return k >= n ? k - n : k;
}

// Whether row v (< n) is among the `len` rows from `start`.
bool range_contains(uint start, uint len, uint n, uint v) {
    return (v >= start ? v - start : v + (n - start)) < len;
}
