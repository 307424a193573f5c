//! Twin of `glsl/surface_delta_tv.comp`: Lδ, the TV on δ (method.md §3.4) over a chunk of the
//! vertex rows ([`DeltaTvChunk`]; the whole grid in the paper preset), as two gather passes over
//! the rows with a per-grid table of axis neighbours (no slot arithmetic, no links lookups):
//! - pass 0: q_v = d_v/√(|d_v|² + 1e-9) for the chunk's rows v, d_v the forward differences of δ
//!   from v to its +x, +y, +z neighbours (0 where there is none: outside the grid or
//!   unallocated);
//! - pass 1: over the chunk's window (its rows and the [`forward_reach`] rows after them),
//!   grad_v += scale·(Σ_a q_{v−e_a}[a] − (q_v.x + q_v.y + q_v.z)), each sum over its terms whose
//!   vertex (v − e_a, or v) is in the chunk. Nothing is flagged: RMSProp updates δ on every row
//!   of the window (`SurfaceRmsProp::delta_rows`).
//!
//! This is ∂(scale·Σ_{v in chunk} TV_v)/∂δ with TV_v = √(|d_v|² + 1e-9); over the whole grid, the
//! value `tv` differentiates (up to rounding: q divides each difference once).

use super::step::RowRange;
use rayon::prelude::*;

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
/// count = rows, a random chunk otherwise. Make it with `surface_reg::delta_tv_chunk`.
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

/// Pass 0: q (3 floats per row) of the chunk's rows; the other rows keep what they held, as in
/// the kernel (pass 1 reads only the chunk's).
pub fn delta_tv_dirs(nbr: &[i32], delta: &[f32], c: &DeltaTvChunk, q: &mut [f32]) {
    c.chunk().par_for_each_mut(q, 3, |v, qv| {
        let d0 = delta[v];
        let n = &nbr[AXIS_NBRS * v..AXIS_NBRS * v + 3];
        let d: [f32; 3] = std::array::from_fn(|a| {
            if n[a] >= 0 {
                delta[n[a] as usize] - d0
            } else {
                0.0
            }
        });
        let tv = (((d[0] * d[0] + d[1] * d[1]) + d[2] * d[2]) + 1e-9).sqrt();
        for a in 0..3 {
            qv[a] = d[a] / tv;
        }
    });
}

/// Pass 1 over the chunk's window (`reach`: [`forward_reach`]): grad += scale·(Σ backward q[a] −
/// Σ own q), each over the terms of the chunk's vertices.
pub fn delta_tv_gather(nbr: &[i32], q: &[f32], grad: &mut [f32], c: &DeltaTvChunk, reach: u32) {
    let chunk = c.chunk();
    c.window(reach).par_for_each_mut(grad, 1, |v, g| {
        let mut back = 0.0f32;
        let mut any = false;
        for a in 0..3 {
            let m = nbr[AXIS_NBRS * v + 3 + a];
            if m >= 0 && chunk.contains(m as usize) {
                back += q[3 * m as usize + a];
                any = true;
            }
        }
        let own = if chunk.contains(v) {
            any = true;
            (q[3 * v] + q[3 * v + 1]) + q[3 * v + 2]
        } else {
            0.0
        };
        if any {
            g[0] += c.scale * (back - own);
        }
    });
}

/// Both passes: grad += ∂(scale·Σ_{chunk} TV)/∂δ. `q`: pass 0's per-row array (3 floats per
/// row, sized here), kept between steps by the CPU backend as the device buffer is.
pub fn delta_tv(
    nbr: &[i32],
    delta: &[f32],
    grad: &mut [f32],
    c: &DeltaTvChunk,
    reach: u32,
    q: &mut Vec<f32>,
) {
    q.resize(3 * delta.len(), 0.0);
    delta_tv_dirs(nbr, delta, c, q);
    delta_tv_gather(nbr, q, grad, c, reach);
}
