//! The chunks of the grid each regulariser works on in a step — TV ([`TvChunk`], both stages),
//! Lδ ([`DeltaTvChunk`]) and Lα ([`OpacityChunk`]) — how the training loop draws them, and the
//! per-grid axis-neighbour table of Lδ.

use crate::abi::consts::TOUCH_OPACITY;
use crate::abi::step::RowRange;
use rayon::prelude::*;

/// Which slots and how much: TV over slots [start, start + count), loss = scale·Σ TV.
#[derive(Clone, Copy, Debug)]
pub struct TvChunk {
    pub res: [u32; 3],
    pub start: u32,
    pub count: u32,
    pub channels: u32,
    pub scale: f32,
    /// Touched-flag bits set on every vertex given a gradient (0: none; step.glsl).
    pub touch: u32,
}

/// Lα over a chunk of allocated vertex rows: rows (start + i) mod rows for i < min(count, rows)
/// (the kernel wraps; `rows` is the allocated vertex count).
#[derive(Clone, Copy, Debug)]
pub struct OpacityChunk {
    pub rows: u32,
    pub start: u32,
    pub count: u32,
    pub lambda: f32,
}

impl OpacityChunk {
    /// The chunk's rows.
    pub fn range(&self) -> RowRange {
        RowRange {
            rows: self.rows,
            start: self.start % self.rows.max(1),
            len: self.count.min(self.rows),
        }
    }
}

/// Entries per row of the axis-neighbour table: +x, +y, +z, −x, −y, −z.
pub const AXIS_NBRS: usize = 6;

/// Per vertex row, the rows of its axis neighbours +x, +y, +z, −x, −y, −z (−1: outside the grid
/// or unallocated). `row_slot`: the slot of each row (`grid::row_slots`).
pub fn axis_neighbours(links: &[i32], row_slot: &[u32], res: [u32; 3]) -> Vec<i32> {
    let (ry, rz) = (res[1] as usize, res[2] as usize);
    let stride = [ry * rz, rz, 1];
    row_slot
        .par_iter()
        .flat_map_iter(|&s| {
            let s = s as usize;
            let v = [s / (ry * rz), (s / rz) % ry, s % rz];
            let fwd = (0..3).map(move |a| {
                if v[a] + 1 < res[a] as usize {
                    links[s + stride[a]]
                } else {
                    -1
                }
            });
            let back = (0..3).map(move |a| if v[a] > 0 { links[s - stride[a]] } else { -1 });
            fwd.chain(back)
        })
        .collect()
}

/// Lδ on the vertex rows (start + i) mod rows, i < count (≤ rows): every vertex's TV term when
/// count = rows, a random chunk otherwise. Make it with [`delta_tv_chunk`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeltaTvChunk {
    pub rows: u32,
    /// First row, < rows.
    pub start: u32,
    /// Rows in the chunk, ≤ rows.
    pub count: u32,
    pub scale: f32,
}

impl DeltaTvChunk {
    /// The chunk's rows.
    pub fn chunk(&self) -> RowRange {
        RowRange {
            rows: self.rows,
            start: self.start,
            len: self.count,
        }
    }

    /// Pass 1's window: the chunk's rows and the `reach` rows after them, at most all; every row
    /// the chunk gives a gradient is in it.
    pub fn window(&self, reach: u32) -> RowRange {
        RowRange {
            len: self.count.saturating_add(reach).min(self.rows),
            ..self.chunk()
        }
    }
}

/// The largest row distance (n − v) mod rows from a vertex row v to one of its +x, +y, +z
/// neighbours n: every row a chunk gives a gradient lies within count + reach rows of its start
/// (small when rows follow the slot order, as stage 2's allocation makes them). Per grid.
pub fn forward_reach(nbr: &[i32]) -> u32 {
    let rows = nbr.len() / AXIS_NBRS;
    nbr.par_chunks(AXIS_NBRS)
        .enumerate()
        .map(|(v, t)| {
            t[..3]
                .iter()
                .filter(|&&n| n >= 0)
                .map(|&n| (n as usize + rows - v) % rows)
                .max()
                .unwrap_or(0) as u32
        })
        .max()
        .unwrap_or(0)
}

/// The [`DeltaTvChunk`] of Lδ (method.md §3.4): TV on δ, forward differences scaled by κ = N/256
/// (N = the largest resolution, the grid's N for cubic grids), mean over a chunk of `fraction`
/// of the `rows` allocated vertices (at least one; every vertex at 1) from row `draw` mod rows:
/// loss_v = κ·√(|d|² + 1e-9) = √(κ²|d|² + κ²·1e-9), which is the definition √(κ²|d|² + 1e-9) up
/// to the ε, so scale = λ·κ/count. A random chunk's mean is an unbiased estimate of the whole
/// grid's (the TVα convention). `draw` is the caller's random number.
pub fn delta_tv_chunk(
    res: [u32; 3],
    rows: u32,
    fraction: f32,
    lambda: f32,
    draw: u64,
) -> DeltaTvChunk {
    let kappa = res.iter().copied().max().unwrap_or(0) as f32 / 256.0;
    let count = ((rows as f64 * fraction as f64).round() as u32).clamp(1, rows.max(1));
    DeltaTvChunk {
        rows,
        start: if count >= rows {
            0
        } else {
            (draw % rows as u64) as u32
        },
        count,
        scale: lambda * kappa / count as f32,
    }
}

/// The [`TvChunk`] of TVα: TV on σα (1 channel) over a contiguous chunk of `frac` of the slots
/// (at least one), starting at `draw` mod (slots − count + 1) so it never runs past the end
/// (tv.comp does not wrap); scale = λ/count, the stage-1 convention. `draw` is the caller's
/// random number.
pub fn opacity_tv_chunk(res: [u32; 3], frac: f32, lambda: f32, draw: u64) -> TvChunk {
    let slots: u32 = res.iter().product();
    let count = ((slots as f64 * frac as f64).round() as u32).clamp(1, slots.max(1));
    let start = (draw % (slots.saturating_sub(count) as u64 + 1)) as u32;
    TvChunk {
        res,
        start,
        count,
        channels: 1,
        scale: lambda / count as f32,
        touch: TOUCH_OPACITY,
    }
}
