//! Twin of `glsl/lib/rmsprop.glsl`: one RMSProp step of one scalar.

/// r ← (r == 0 ? g² : βr + (1 − β)g²); θ ← θ − lr·g/(√r + ε); g ← 0.
pub fn rmsprop_one(p: &mut f32, g: &mut f32, r: &mut f32, lr: f32, beta: f32, eps: f32) {
    let g2 = *g * *g;
    let rn = if *r == 0.0 {
        g2
    } else {
        beta * *r + (1.0 - beta) * g2
    };
    *r = rn;
    *p -= lr * *g / (rn.sqrt() + eps);
    *g = 0.0;
}
