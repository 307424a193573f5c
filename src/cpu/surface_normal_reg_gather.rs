//! Twin of `glsl/surface_normal_reg_gather.comp`, pass 3 of Ln1 + Ln2 (`cpu::surface_reg`).

use crate::abi::consts::{NBR_B, NBR_STRIDE};
use crate::abi::normal_reg::{work_rows, NormalChunk, NormalPrefix, CORNERS_STRIDE};
use rayon::prelude::*;

/// Pass 3, twin of `surface_normal_reg_gather`: each vertex v (row r) of the chunk's corner work
/// (`c.corners_work`) sums corner b of its cells v − b (b = 0..7 in order; those that are rows in
/// the chunk's window and in a kept pair, i.e. not +∞); where it has such a cell, grad[r] += the
/// sum and touched[r] |= `c.touch`.
pub fn normal_gather(
    p: &NormalPrefix,
    corners: &[f32],
    grad: &mut [f32],
    touched: &mut [u32],
    c: &NormalChunk,
) {
    let work = work_rows(p.corner_rows(), c.corners_work);
    let window = c.rows_from_start(c.window);
    let sums: Vec<Option<f32>> = work
        .par_iter()
        .map(|&r| {
            let r = r as usize;
            let nb = &p.neighbours()[NBR_STRIDE * r..][..NBR_STRIDE];
            let mut sum = 0f32;
            let mut hit = false;
            let mut l = [r as i32; 8];
            for j in 1..8 {
                l[NBR_B[j]] = nb[8 + j];
            }
            for (b, &l) in l.iter().enumerate() {
                if l < 0 || !window.contains(l as usize) {
                    continue;
                }
                let c = corners[CORNERS_STRIDE * l as usize + b];
                if c == f32::INFINITY {
                    continue;
                }
                hit = true;
                sum += c;
            }
            hit.then_some(sum)
        })
        .collect();
    for (&r, sum) in work.iter().zip(sums) {
        if let Some(sum) = sum {
            grad[r as usize] += sum;
            touched[r as usize] |= c.touch;
        }
    }
}
