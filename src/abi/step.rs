//! The step record (`glsl/lib/step.glsl`) as the host lays it out and reads it, and the ranges
//! of vertex rows ([`RowRange`]) that the stage-2 regularisers and RMSProp work on.

use rayon::prelude::*;
use std::ops::Range;

use crate::abi::buffers::StepHeader;

/// Index in u32 words of the touched flags in the step record: after its header.
pub const STEP_FLAGS: usize = std::mem::size_of::<StepHeader>() / 4;

/// Bytes from the start of the step record that a step starts from zero: the header's touched
/// count and counters, which precede `n`.
pub const STEP_RESET_BYTES: u64 = std::mem::offset_of!(StepHeader, n) as u64;

const _: () = assert!(
    std::mem::offset_of!(StepHeader, count) < STEP_RESET_BYTES as usize
        && std::mem::offset_of!(StepHeader, stats) < STEP_RESET_BYTES as usize
);

/// A step record (glsl/lib/step.glsl) for `n` vertices, as u32 words: the header with `touched`'s
/// count, then the flags and the list with `touched`'s (vertex, flag bits) in list order.
pub fn step_record(n: usize, touched: &[(usize, u32)]) -> Vec<u32> {
    let head = StepHeader {
        count: touched.len() as u32,
        n: n as u32,
        ..Default::default()
    };
    let mut v: Vec<u32> = bytemuck::cast_slice(&[head]).to_vec();
    v.resize(STEP_FLAGS + 2 * n, 0);
    for (i, &(vertex, bits)) in touched.iter().enumerate() {
        v[STEP_FLAGS + vertex] = bits;
        v[STEP_FLAGS + n + i] = vertex as u32;
    }
    v
}

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

    /// The range as two disjoint spans of rows, in order: the rows from start, then those
    /// wrapped past the last row (empty unless it wraps).
    pub fn spans(&self) -> [Range<usize>; 2] {
        let (rows, start) = (self.rows as usize, self.start as usize);
        let end = start + self.len as usize;
        [start..end.min(rows), 0..end.saturating_sub(rows)]
    }

    /// `f(row, item)` in parallel for every row of the range, item = the row's `stride` entries
    /// of `data`.
    pub fn par_for_each_mut<T: Send>(
        &self,
        data: &mut [T],
        stride: usize,
        f: impl Fn(usize, &mut [T]) + Sync,
    ) {
        for span in self.spans() {
            data[stride * span.start..stride * span.end]
                .par_chunks_mut(stride)
                .enumerate()
                .for_each(|(i, item)| f(span.start + i, item));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn step_record_lays_out_header_flags_and_list() {
        let v = step_record(5, &[(3, 2), (0, 1)]);
        assert_eq!(v.len(), STEP_FLAGS + 10);
        let head: StepHeader = bytemuck::pod_read_unaligned(bytemuck::cast_slice(&v[..STEP_FLAGS]));
        assert_eq!((head.count, head.n), (2, 5));
        assert_eq!(head.stats, Default::default());
        assert_eq!(&v[STEP_FLAGS..STEP_FLAGS + 5], [1, 0, 0, 2, 0]);
        assert_eq!(&v[STEP_FLAGS + 5..STEP_FLAGS + 7], [3, 0]);
    }

    #[test]
    fn row_ranges_visit_each_row_once() {
        // Inside, wrapping past the last row, every row, none.
        for (start, len) in [(2, 5), (7, 6), (0, 10), (4, 10), (3, 0)] {
            let r = RowRange {
                rows: 10,
                start,
                len,
            };
            let mut seen = vec![0u32; 20];
            r.par_for_each_mut(&mut seen, 2, |v, item| {
                item[0] += 1;
                item[1] = v as u32;
            });
            for v in 0..10 {
                let want = u32::from(r.contains(v) && len > 0);
                assert_eq!(seen[2 * v], want, "{start}+{len}: row {v}");
                assert_eq!(seen[2 * v + 1], if want == 1 { v as u32 } else { 0 });
            }
            let n: usize = r.spans().iter().map(|s| s.len()).sum();
            assert_eq!(n, len as usize);
        }
    }
}
