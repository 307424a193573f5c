//! Twin of `glsl/lib/step.glsl`: the per-step touched-vertex flags (the CPU keeps only the flags;
//! the list order of the GPU is irrelevant to the result) and the kernel `optim_args`.

use std::sync::atomic::{AtomicU32, Ordering};

/// Step-buffer layout (u32 indices), as in step.glsl: touched count, 4 counters (samples shaded,
/// empty, skipped; gradient atomic adds), vertex count, then the flags (n) and the list (n).
pub const STEP_COUNT: usize = 0;
pub const STEP_STATS: usize = 1;
pub const STEP_N: usize = 5;
pub const STEP_FLAGS: usize = 8;

/// Touched-flag bits, as in step.glsl: stage 1's one group, stage 2's three.
pub const TOUCH_ALL: u32 = 1;
pub const TOUCH_DELTA: u32 = 1;
pub const TOUCH_OPACITY: u32 = 2;
pub const TOUCH_SH: u32 = 4;
/// Every stage-2 group.
pub const TOUCH_SURFACE: u32 = TOUCH_DELTA | TOUCH_OPACITY | TOUCH_SH;

/// The vertex rows (start + i) mod rows, i < len (start < rows, len ≤ rows; len = 0: none) —
/// the chunks of the stage-2 regularisers and the rows whose δ RMSProp updates densely.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RowRange {
    pub rows: u32,
    pub start: u32,
    pub len: u32,
}

impl RowRange {
    /// Every row.
    pub fn all(rows: u32) -> Self {
        RowRange {
            rows,
            start: 0,
            len: rows,
        }
    }

    /// Whether row v is in the range.
    pub fn contains(&self, v: usize) -> bool {
        let (rows, start) = (self.rows as usize, self.start as usize);
        let i = if v >= start {
            v - start
        } else {
            v + rows - start
        };
        i < self.len as usize
    }

    /// Row i of the range (i < len; wraps past the last row).
    pub fn row(&self, i: u32) -> usize {
        ((self.start as u64 + i as u64) % self.rows.max(1) as u64) as usize
    }
}

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

/// Twin of `optim_args.comp`: indirect dispatch arguments for `count` touched vertices.
pub fn optim_args(count: u32) -> [u32; 3] {
    let groups = count.div_ceil(64);
    let gx = groups.min(32768);
    [gx, if gx == 0 { 0 } else { groups.div_ceil(gx) }, 1]
}
