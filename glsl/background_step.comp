#version 460
// background_step — one RMSProp step of the learned background colour (src/abi/buffers.rs
// `Background`), after the training kernel of the step has added its gradient:
// r ← (r == 0 ? g² : β·r + (1 − β)·g²); rgb ← clamp(rgb − lr·g/(√r + ε), 0, 1); g ← 0.
// The clamp keeps the colour in the range of the images it is composited with (a projected
// gradient step): black and white backdrops are reachable exactly, which a sigmoid
// parametrisation would only approach with a vanishing gradient.
// Thread mapping: one invocation per channel (3).
// CPU twin: `cpu::background_step::background_step`.
#include "common.glsl"
layout(local_size_x = 4) in;

layout(push_constant, scalar) uniform Push {
    BackgroundBuf bg;
    float lr;
    float beta;
    float eps;
} pc;

void main() {
    uint ch = flat_id();
    if (ch >= 3u) return;
    float g = pc.bg.v[0].grad[ch];
    float r = pc.bg.v[0].avg[ch];
    precise float g2 = g * g;
    precise float rn = r == 0.0 ? g2 : pc.beta * r + (1.0 - pc.beta) * g2;
    precise float step = pc.lr * g / (sqrt(rn) + pc.eps);
    precise float v = pc.bg.v[0].rgb[ch] - step;
    pc.bg.v[0].avg[ch] = rn;
    pc.bg.v[0].rgb[ch] = clamp(v, 0.0, 1.0);
    pc.bg.v[0].grad[ch] = 0.0;
}
