//! The normal regulariser Ln1 + Ln2 (method.md §3.4) as its kernels are given it: the chunk of
//! a step ([`NormalChunk`]) and the grid's neighbour table and work lists ([`NormalPrefix`]),
//! built on the host for both backends.

use crate::abi::consts::{NBR_B, NBR_STRIDE, TOUCH_DELTA};
use crate::abi::step::RowRange;
use rayon::prelude::*;

/// Ln1 + Ln2 over the cells of a chunk of allocated vertex rows: (start + i) mod rows for
/// i < min(count, rows); a cell is named by its lower corner vertex (row r, slot row_slot[r]).
/// `cells` is the mean's denominator M (cells of the chunk with an existing forward neighbour):
/// make chunks with [`NormalPrefix::chunk`].
#[derive(Clone, Copy, Debug)]
pub struct NormalChunk {
    pub res: [u32; 3],
    pub rows: u32,
    pub start: u32,
    pub count: u32,
    pub cells: u32,
    pub lambda1: f32,
    pub lambda2: f32,
    /// Touched-flag bits set on the vertices given a gradient (0: none; step.glsl).
    pub touch: u32,
    /// The rows from start whose cells the cells and pairs passes visit: the chunk's rows and
    /// the cells' forward reach after them (at most all rows); every cell in a pair with a chunk
    /// cell is among them.
    pub window: u32,
    /// The rows from start of the corners of those cells (the window widened by the corners'
    /// reach): every row the chunk gives a gradient is among them.
    pub corner_window: u32,
    /// The passes' work as (first, n) ranges of the ascending work lists (wrapping past the
    /// end): the cells of the window (`NormalPrefix::cell_rows`) and the corners of those cells
    /// (`NormalPrefix::corner_rows`, the window widened by the corners' reach).
    pub cells_work: (u32, u32),
    pub corners_work: (u32, u32),
}

impl NormalChunk {
    /// The `len` rows from the chunk's start.
    pub fn rows_from_start(&self, len: u32) -> RowRange {
        RowRange {
            rows: self.rows,
            start: self.start % self.rows.max(1),
            len,
        }
    }
}

/// The entries of a work range (first, n) of `list` (wrapping past its end), in order.
pub fn work_rows(list: &[u32], work: (u32, u32)) -> Vec<u32> {
    list.iter()
        .cycle()
        .skip(work.0 as usize)
        .take(work.1 as usize)
        .copied()
        .collect()
}

/// The (first, n) range of the entries of the ascending `list` in rows [start, start + len) mod
/// rows (start < rows, len ≤ rows).
fn list_range(list: &[u32], rows: u32, start: u32, len: u32) -> (u32, u32) {
    let below = |r: u32| list.partition_point(|&x| x < r) as u32;
    let first = below(start);
    let n = if start + len <= rows {
        below(start + len) - first
    } else {
        (list.len() as u32 - first) + below(start + len - rows)
    };
    (first, n)
}

/// Floats per row of the normals ((n, status + 4·k)) and corners (∂L/∂δ of the 8 corners, +∞
/// for a cell in no kept pair) arrays.
pub const NORMALS_STRIDE: usize = 4;
pub const CORNERS_STRIDE: usize = 8;

/// The normal regulariser's neighbour table of every row (see [`NBR_STRIDE`]): the rows of the
/// vertices v ± b and k, the number of existing forward neighbour cells of the cell v (a cell
/// exists when it lies inside the grid and its 8 corners are allocated; k = 0 when the cell
/// does not). Depends on the allocation only.
pub fn normal_neighbours(links: &[i32], row_slot: &[u32], res: [u32; 3]) -> Vec<i32> {
    let (ry, rz) = (res[1] as usize, res[2] as usize);
    let mut nbr = vec![-1i32; NBR_STRIDE * row_slot.len()];
    nbr.par_chunks_mut(NBR_STRIDE)
        .zip(row_slot)
        .for_each(|(t, &s)| {
            let s = s as usize;
            let v = [s / (ry * rz), (s / rz) % ry, s % rz];
            for (j, &b) in NBR_B.iter().enumerate().skip(1) {
                let o = [(b >> 2) & 1, (b >> 1) & 1, b & 1];
                let off = (o[0] * ry + o[1]) * rz + o[2];
                if (0..3).all(|a| v[a] + o[a] < res[a] as usize) {
                    t[j] = links[s + off];
                }
                if (0..3).all(|a| v[a] >= o[a]) {
                    t[8 + j] = links[s - off];
                }
            }
        });
    // k: the cell exists when its 7 other corners are rows; its forward neighbours are the cells
    // of its corners 1, 2, 4 (entries 1, 2, 3).
    let exists = |r: usize| (1..8).all(|j| nbr[NBR_STRIDE * r + j] >= 0);
    let k: Vec<i32> = (0..row_slot.len())
        .into_par_iter()
        .map(|r| {
            if !exists(r) {
                return 0;
            }
            (1..4)
                .filter(|&j| exists(nbr[NBR_STRIDE * r + j] as usize))
                .count() as i32
        })
        .collect();
    for (t, k) in nbr.chunks_mut(NBR_STRIDE).zip(k) {
        t[0] = k;
    }
    nbr
}

/// Per-grid data of the normal regularisers: the neighbour table ([`normal_neighbours`]), the
/// work lists of the passes, and a prefix count of the rows whose cell has an existing forward
/// neighbour, which gives the denominator M of any row chunk. Depends on the allocation only:
/// build it once per grid.
pub struct NormalPrefix {
    res: [u32; 3],
    nbr: Vec<i32>,
    /// The rows whose cell exists, ascending.
    cell_rows: Vec<u32>,
    /// The rows that are a corner of an existing cell, ascending.
    corner_rows: Vec<u32>,
    /// prefix[r] = number of such rows below r (rows + 1 entries).
    prefix: Vec<u32>,
    /// The largest row distance (mod rows) from a cell to a forward face neighbour, and from a
    /// corner row v to a cell v − b it is a corner of: the windows of the passes.
    cell_reach: u32,
    corner_reach: u32,
}

impl NormalPrefix {
    pub fn new(links: &[i32], row_slot: &[u32], res: [u32; 3]) -> NormalPrefix {
        let nbr = normal_neighbours(links, row_slot, res);
        let mut prefix = Vec::with_capacity(row_slot.len() + 1);
        prefix.push(0);
        let (mut cell_rows, mut corner) = (Vec::new(), vec![false; row_slot.len()]);
        for (r, t) in nbr.chunks(NBR_STRIDE).enumerate() {
            prefix.push(prefix.last().copied().unwrap_or(0) + (t[0] > 0) as u32);
            if t[1..8].iter().all(|&l| l >= 0) {
                cell_rows.push(r as u32);
                corner[r] = true;
                for &l in &t[1..8] {
                    corner[l as usize] = true;
                }
            }
        }
        let corner_rows: Vec<u32> = (0..row_slot.len() as u32)
            .filter(|&r| corner[r as usize])
            .collect();
        let rows = row_slot.len();
        let dist = |from: usize, to: i32| (to as usize + rows - from) % rows;
        let cell_reach = cell_rows
            .iter()
            .flat_map(|&r| {
                let t = &nbr[NBR_STRIDE * r as usize..][..NBR_STRIDE];
                (1..4).map(move |j| dist(r as usize, t[j]))
            })
            .max()
            .unwrap_or(0) as u32;
        let is_cell = |l: i32| {
            l >= 0
                && nbr[NBR_STRIDE * l as usize + 1..][..7]
                    .iter()
                    .all(|&x| x >= 0)
        };
        let corner_reach = corner_rows
            .iter()
            .flat_map(|&v| {
                let t = &nbr[NBR_STRIDE * v as usize..][..NBR_STRIDE];
                (1..8)
                    .map(move |j| t[8 + j])
                    .filter(|&l| is_cell(l))
                    .map(move |l| dist(l as usize, v as i32))
            })
            .max()
            .unwrap_or(0) as u32;
        NormalPrefix {
            res,
            nbr,
            cell_rows,
            corner_rows,
            prefix,
            cell_reach,
            corner_reach,
        }
    }

    /// The neighbour table ([`normal_neighbours`]).
    pub fn neighbours(&self) -> &[i32] {
        &self.nbr
    }

    /// The rows whose cell exists (the work of the cells and pairs passes), ascending.
    pub fn cell_rows(&self) -> &[u32] {
        &self.cell_rows
    }

    /// The rows that are a corner of an existing cell (the work of the gather pass), ascending.
    pub fn corner_rows(&self) -> &[u32] {
        &self.corner_rows
    }

    /// The number of allocated rows.
    pub fn rows(&self) -> u32 {
        (self.prefix.len() - 1) as u32
    }

    /// The chunk of `count` rows from `start` (rows (start + i) mod rows, i < min(count, rows)),
    /// with its M, flagging δ touched (set `touch` to change that).
    pub fn chunk(&self, start: u32, count: u32, lambda1: f32, lambda2: f32) -> NormalChunk {
        let rows = self.rows();
        let n = count.min(rows);
        let s0 = if rows == 0 { 0 } else { start % rows };
        let p = |r: u32| self.prefix[r as usize];
        let cells = if s0 + n <= rows {
            p(s0 + n) - p(s0)
        } else {
            (p(rows) - p(s0)) + p(s0 + n - rows)
        };
        let window = n.saturating_add(self.cell_reach).min(rows);
        let corner_window = window.saturating_add(self.corner_reach).min(rows);
        NormalChunk {
            res: self.res,
            rows,
            start,
            count,
            cells,
            lambda1,
            lambda2,
            touch: TOUCH_DELTA,
            window,
            corner_window,
            cells_work: list_range(&self.cell_rows, rows, s0, window),
            corners_work: list_range(&self.corner_rows, rows, s0, corner_window),
        }
    }
}
