//! Twin of `glsl/lib/step.glsl`'s touched-vertex flags (the CPU keeps only the flags; the list
//! order of the GPU is irrelevant to the result).

use crate::abi::consts::TOUCH_ALL;
use std::sync::atomic::{AtomicU32, Ordering};

/// Set the bits `m` of vertex v's flag.
pub fn touch_mask(flags: &[AtomicU32], v: usize, m: u32) {
    if m != 0 {
        flags[v].fetch_or(m, Ordering::Relaxed);
    }
}

/// Mark vertex v touched (every group).
pub fn touch(flags: &[AtomicU32], v: usize) {
    touch_mask(flags, v, TOUCH_ALL);
}
