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

use crate::abi::regularisers::{DeltaTvChunk, AXIS_NBRS};

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
