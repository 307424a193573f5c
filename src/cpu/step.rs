//! Twin of `glsl/lib/step.glsl`: the per-step touched-vertex flags (the CPU keeps only the flags;
//! the list order of the GPU is irrelevant to the result) and the kernel `optim_args`.

use std::sync::atomic::{AtomicU32, Ordering};

/// Step-buffer layout (u32 indices), as in step.glsl: touched count, 4 counters (samples shaded,
/// empty, skipped; gradient atomic adds), vertex count, then the flags (n) and the list (n).
pub const STEP_COUNT: usize = 0;
pub const STEP_STATS: usize = 1;
pub const STEP_N: usize = 5;
pub const STEP_FLAGS: usize = 8;

/// Mark vertex v touched.
pub fn touch(flags: &[AtomicU32], v: usize) {
    flags[v].store(1, Ordering::Relaxed);
}

/// Twin of `optim_args.comp`: indirect dispatch arguments for `count` touched vertices.
pub fn optim_args(count: u32) -> [u32; 3] {
    let groups = count.div_ceil(64);
    let gx = groups.min(32768);
    [gx, if gx == 0 { 0 } else { groups.div_ceil(gx) }, 1]
}
