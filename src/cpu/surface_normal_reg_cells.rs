//! Twin of `glsl/surface_normal_reg_cells.comp`, pass 1 of Ln1 + Ln2 (`cpu::surface_reg`).

use crate::abi::consts::{NBR_B, NBR_STRIDE, TINY_NORMAL2};
use crate::abi::normal_reg::{work_rows, NormalChunk, NormalPrefix, NORMALS_STRIDE};
use rayon::prelude::*;

/// Pass 1, twin of `surface_normal_reg_cells`: normals[r] = (n, status + 4·k) of the cells of
/// the chunk's window (`c.cells_work`); the other rows keep what they held, as in the kernel
/// (the pairs pass reads only the window's).
pub fn normal_cells(p: &NormalPrefix, delta: &[f32], c: &NormalChunk, normals: &mut [f32]) {
    let work = work_rows(p.cell_rows(), c.cells_work);
    let computed: Vec<[f32; NORMALS_STRIDE]> = work
        .par_iter()
        .map(|&r| {
            let r = r as usize;
            let t = &p.neighbours()[NBR_STRIDE * r..][..NBR_STRIDE];
            let mut d = [delta[r]; 8];
            for j in 1..8 {
                d[NBR_B[j]] = delta[t[j] as usize];
            }
            let mx = ((d[4] + d[5]) + (d[6] + d[7])) - ((d[0] + d[1]) + (d[2] + d[3]));
            let my = ((d[2] + d[3]) + (d[6] + d[7])) - ((d[0] + d[1]) + (d[4] + d[5]));
            let mz = ((d[1] + d[3]) + (d[5] + d[7])) - ((d[0] + d[2]) + (d[4] + d[6]));
            let n = [mx * 0.25, my * 0.25, mz * 0.25];
            let n2 = (n[0] * n[0] + n[1] * n[1]) + n[2] * n[2];
            let status = if n2 <= TINY_NORMAL2 { 1 } else { 2 };
            [n[0], n[1], n[2], (status + 4 * t[0] as u32) as f32]
        })
        .collect();
    for (&r, v) in work.iter().zip(&computed) {
        normals[NORMALS_STRIDE * r as usize..][..NORMALS_STRIDE].copy_from_slice(v);
    }
}
