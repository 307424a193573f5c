// Point record written by extract_points.comp (scalar layout, 40 bytes). Rust twin:
// `cpu::extract_points::ExtractPoint` (same field order).
#ifndef EXTRACT_GLSL
#define EXTRACT_GLSL

struct ExtractPoint {
    vec3 local;  // position in the cell, [0,1]^3
    vec3 grad;   // gradient of the trilerped field at `local`, d/d(local), not normalised
    float alpha; // 1 - exp(-max(opacity, 0)); 1 without an opacity field
    uint cell;   // links slot of the cell's corner 000
    uint level;  // index into the level list
    uint ray;    // axis * R^2 + iu * R + iv
};

layout(buffer_reference, scalar, buffer_reference_align = 4) buffer ExtractPointBuf { ExtractPoint v[]; };

#endif
