//! The normal regulariser Ln1 + Ln2 (method.md §3.4) on the CPU: its chunk ([`NormalChunk`]) and
//! the grid's neighbour table and work lists ([`NormalPrefix`]), and its three kernels' twins
//! (`cpu::surface_normal_reg_{cells,pairs,gather}`, with `glsl/lib/normal_reg.glsl`) run in turn;
//! also the value of a TV chunk ([`tv_loss`]). The passes ADD their gradient and flag the
//! vertices they give one in `touched` (the twin of step.glsl's `touch_mask`) unless RMSProp's δ
//! rows cover them.

use super::surface_normal_reg_cells::normal_cells;
use super::surface_normal_reg_gather::normal_gather;
use super::surface_normal_reg_pairs::{normal_pairs, NormalRegStats};
use crate::abi::normal_reg::{NormalChunk, NormalPrefix, CORNERS_STRIDE, NORMALS_STRIDE};
use crate::abi::regularisers::TvChunk;
use rayon::prelude::*;

/// The per-row arrays the passes leave behind (layouts in glsl/lib/normal_reg.glsl), kept
/// between steps as the device buffers are: each pass writes only its window's rows.
#[derive(Default)]
pub struct NormalScratch {
    pub normals: Vec<f32>,
    pub corners: Vec<f32>,
}

impl NormalScratch {
    /// Sized for `rows` vertex rows; new entries start at 0 (normals) and +∞ (corners).
    fn fit(&mut self, rows: usize) {
        self.normals.resize(NORMALS_STRIDE * rows, 0.0);
        self.corners.resize(CORNERS_STRIDE * rows, f32::INFINITY);
    }
}

/// The three passes with the grid's [`NormalPrefix`] (neighbour table, work lists) on the
/// per-row arrays `scratch` (sized here): as [`surface_normal_reg`], also leaving the arrays
/// (for the parity checks).
pub fn normal_reg_passes(
    p: &NormalPrefix,
    delta: &[f32],
    grad: &mut [f32],
    touched: &mut [u32],
    c: &NormalChunk,
    scratch: &mut NormalScratch,
) -> NormalRegStats {
    scratch.fit(p.rows() as usize);
    normal_cells(p, delta, c, &mut scratch.normals);
    let st = normal_pairs(p, &scratch.normals, c, &mut scratch.corners);
    normal_gather(p, &scratch.corners, grad, touched, c);
    st
}

/// Ln1 + Ln2 (definition in `glsl/surface_normal_reg_pairs.comp`) in the kernels' three passes,
/// cell normals, pairs, gather (no atomics), with the grid's [`NormalPrefix`] built here
/// (callers that keep one call [`normal_reg_passes`]). Adds ∂loss/∂δ to `grad`
/// and sets the `touch` bits of the corners of every cell in a kept pair. Nothing is done for an
/// empty chunk.
pub fn surface_normal_reg(
    links: &[i32],
    row_slot: &[u32],
    delta: &[f32],
    grad: &mut [f32],
    touched: &mut [u32],
    c: &NormalChunk,
) -> NormalRegStats {
    if c.count.min(c.rows) == 0 {
        return NormalRegStats::default();
    }
    let p = NormalPrefix::new(links, row_slot, c.res);
    normal_reg_passes(&p, delta, grad, touched, c, &mut NormalScratch::default())
}

/// The value scale·Σ TV of a TV chunk (f64 sum of f32 TV terms, as [`super::tv`] differentiates
/// it), for logging Lδ and TVα.
pub fn tv_loss(links: &[i32], data: &[f32], c: &TvChunk) -> f64 {
    let (ry, rz) = (c.res[1] as usize, c.res[2] as usize);
    let n = c.channels as usize;
    let end = (c.start as usize + c.count as usize).min(links.len());
    let sum: f64 = (c.start as usize..end)
        .into_par_iter()
        .map(|s| {
            let l = links[s];
            if l < 0 {
                return 0.0;
            }
            let v = [s / (ry * rz), (s / rz) % ry, s % rz];
            (0..n)
                .map(|ch| {
                    let v0 = data[l as usize * n + ch];
                    let mut d2 = 0f32;
                    for a in 0..3 {
                        let stride = [ry * rz, rz, 1][a];
                        if v[a] + 1 < c.res[a] as usize && links[s + stride] >= 0 {
                            let d = data[links[s + stride] as usize * n + ch] - v0;
                            d2 += d * d;
                        }
                    }
                    (d2 + 1e-9).sqrt() as f64
                })
                .sum::<f64>()
        })
        .sum();
    c.scale as f64 * sum
}
