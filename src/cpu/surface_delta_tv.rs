//! Twin of `glsl/surface_delta_tv.comp`: Lδ, the TV on δ over every allocated vertex (method.md
//! §3.4; scale as [`super::surface_reg::delta_tv_chunk`]), as two gather passes over the vertex
//! rows with a per-grid table of axis neighbours (no slot arithmetic, no links lookups):
//! - pass 0: q_v = d_v/√(|d_v|² + 1e-9), d_v the forward differences of δ from v to its +x, +y, +z
//!   neighbours (0 where there is none: outside the grid or unallocated);
//! - pass 1: grad_v += scale·(Σ_a q_{v−e_a}[a] − (q_v.x + q_v.y + q_v.z)), the sum over the
//!   backward neighbours that exist.
//!
//! This is ∂(scale·Σ_v TV_v)/∂δ with TV_v = √(|d_v|² + 1e-9), the value `tv` differentiates over
//! the whole grid (up to rounding: q divides each difference once).

use rayon::prelude::*;

/// Entries per row of the axis-neighbour table: +x, +y, +z, −x, −y, −z.
pub const AXIS_NBRS: usize = 6;

/// Per vertex row, the rows of its axis neighbours +x, +y, +z, −x, −y, −z (−1: outside the grid
/// or unallocated). `row_slot`: the slot of each row (`surface_reg::row_slots`).
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

/// Pass 0: q (3 floats per row).
pub fn delta_tv_dirs(nbr: &[i32], delta: &[f32]) -> Vec<f32> {
    delta
        .par_iter()
        .enumerate()
        .flat_map_iter(|(v, &d0)| {
            let n = &nbr[AXIS_NBRS * v..AXIS_NBRS * v + 3];
            let d: [f32; 3] = std::array::from_fn(|a| {
                if n[a] >= 0 {
                    delta[n[a] as usize] - d0
                } else {
                    0.0
                }
            });
            let tv = (((d[0] * d[0] + d[1] * d[1]) + d[2] * d[2]) + 1e-9).sqrt();
            d.map(|x| x / tv)
        })
        .collect()
}

/// Pass 1: grad += scale·(Σ backward q[a] − Σ own q).
pub fn delta_tv_gather(nbr: &[i32], q: &[f32], grad: &mut [f32], scale: f32) {
    grad.par_iter_mut().enumerate().for_each(|(v, g)| {
        let mut back = 0.0f32;
        for a in 0..3 {
            let m = nbr[AXIS_NBRS * v + 3 + a];
            if m >= 0 {
                back += q[3 * m as usize + a];
            }
        }
        let own = (q[3 * v] + q[3 * v + 1]) + q[3 * v + 2];
        *g += scale * (back - own);
    });
}

/// Both passes: grad += ∂(scale·Σ TV)/∂δ.
pub fn delta_tv(nbr: &[i32], delta: &[f32], grad: &mut [f32], scale: f32) {
    let q = delta_tv_dirs(nbr, delta);
    delta_tv_gather(nbr, &q, grad, scale);
}
