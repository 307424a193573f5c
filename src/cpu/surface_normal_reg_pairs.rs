//! Twin of `glsl/surface_normal_reg_pairs.comp`, pass 2 of Ln1 + Ln2 (`cpu::surface_reg`).

use crate::abi::consts::NBR_STRIDE;
use crate::abi::normal_reg::{
    work_rows, NormalChunk, NormalPrefix, CORNERS_STRIDE, NORMALS_STRIDE,
};
use rayon::prelude::*;

fn norm3(n: [f32; 3]) -> f32 {
    ((n[0] * n[0] + n[1] * n[1]) + n[2] * n[2]).sqrt()
}

/// ∂n/∂δ_b contracted with gn: Σ_a gn_a·(bit_a(b) ? +¼ : −¼).
fn corner_grad(b: usize, gn: [f32; 3]) -> f32 {
    let q = gn.map(|x| x * 0.25);
    let s = |bit: usize, x: f32| if bit != 0 { x } else { -x };
    (s((b >> 2) & 1, q[0]) + s((b >> 1) & 1, q[1])) + s(b & 1, q[2])
}

/// GLSL sign(): 0 at 0.
fn sign0(x: f32) -> f32 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        0.0
    }
}

/// What one call of `cpu::surface_reg::surface_normal_reg` found.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NormalRegStats {
    /// The loss (f64 sum of the per-cell f32 terms).
    pub loss: f64,
    /// Pairs skipped because a normal was tiny (|n|² ≤ [`TINY_NORMAL2`]).
    pub skipped: u32,
}

/// A normals entry: (n, status, k).
fn read_normal(normals: &[f32], r: usize) -> ([f32; 3], u32, u32) {
    let e = &normals[NORMALS_STRIDE * r..][..NORMALS_STRIDE];
    let w = e[3] as u32;
    ([e[0], e[1], e[2]], w & 3, w >> 2)
}

/// Twin of `surface_normal_reg_pairs`'s pair_grad: w·(λ1·sign(d) + 2λ2·d).
fn pair_grad(c: &NormalChunk, w: f32, d: [f32; 3]) -> [f32; 3] {
    d.map(|x| w * (c.lambda1 * sign0(x) + (2.0 * c.lambda2) * x))
}

/// Twin of `surface_normal_reg_pairs`'s `cell_term` for row r: writes its corners (`out`),
/// returns its loss share and its skipped forward pairs.
fn cell_pairs(
    nbr: &[i32],
    normals: &[f32],
    c: &NormalChunk,
    r: usize,
    out: &mut [f32],
) -> (f64, u32) {
    let chunk = c.rows_from_start(c.count.min(c.rows));
    let in_chunk = |r: usize| chunk.contains(r);
    let t = &nbr[NBR_STRIDE * r..][..NBR_STRIDE];
    let (nc, st, k) = read_normal(normals, r);
    let rc = norm3(nc);
    let n_c = nc.map(|x| x / rc);
    let mut g = [0f32; 3];
    let mut member = false;
    let (mut loss, mut skipped) = (0.0, 0u32);
    if st != 0 && in_chunk(r) {
        // The forward face neighbours along x, y, z (entries 3, 2, 1): corners of the cell, so
        // rows.
        let nb: [([f32; 3], bool); 3] = std::array::from_fn(|a| {
            let (nn, sn, _) = read_normal(normals, t[3 - a] as usize);
            let ok = sn == 2 && st == 2;
            if sn != 0 && !ok {
                skipped += 1;
            }
            (nn, ok)
        });
        if nb.iter().any(|x| x.1) {
            let w = 1.0 / (k as f32 * c.cells as f32);
            let mut lsum = 0f32;
            for &(nn, ok) in &nb {
                if !ok {
                    continue;
                }
                let r_n = norm3(nn);
                let d: [f32; 3] = std::array::from_fn(|j| n_c[j] - nn[j] / r_n);
                let l1 = (d[0].abs() + d[1].abs()) + d[2].abs();
                let l2 = (d[0] * d[0] + d[1] * d[1]) + d[2] * d[2];
                lsum += c.lambda1 * l1 + c.lambda2 * l2;
                let gp = pair_grad(c, w, d);
                for j in 0..3 {
                    g[j] += gp[j];
                }
            }
            member = true;
            loss = (w * lsum) as f64;
        }
    }
    if st == 2 {
        // The backward face neighbours along x, y, z (entries 11, 10, 9).
        for a in 0..3 {
            let l = t[11 - a];
            if l < 0 {
                continue;
            }
            let (nb, sb, kb) = read_normal(normals, l as usize);
            if sb != 2 || !in_chunk(l as usize) {
                continue;
            }
            let w = 1.0 / (kb as f32 * c.cells as f32);
            let r_b = norm3(nb);
            let d: [f32; 3] = std::array::from_fn(|j| nb[j] / r_b - n_c[j]);
            let gp = pair_grad(c, w, d);
            for j in 0..3 {
                g[j] -= gp[j];
            }
            member = true;
        }
    }
    if member {
        let p = (n_c[0] * g[0] + n_c[1] * g[1]) + n_c[2] * g[2];
        let u: [f32; 3] = std::array::from_fn(|j| (g[j] - n_c[j] * p) / rc);
        for (b, o) in out.iter_mut().enumerate() {
            *o = corner_grad(b, u);
        }
    } else {
        out.fill(f32::INFINITY);
    }
    (loss, skipped)
}

/// Pass 2, twin of `surface_normal_reg_pairs`: the corners (∂L/∂δ of the cell's 8 corners from
/// its kept pairs, +∞ for a cell in none) of the cells of the chunk's window; the other rows
/// keep what they held, as in the kernel (the gather reads only the window's). Returns the loss
/// and the skipped pairs.
pub fn normal_pairs(
    p: &NormalPrefix,
    normals: &[f32],
    c: &NormalChunk,
    corners: &mut [f32],
) -> NormalRegStats {
    let work = work_rows(p.cell_rows(), c.cells_work);
    let computed: Vec<([f32; CORNERS_STRIDE], f64, u32)> = work
        .par_iter()
        .map(|&r| {
            let mut out = [0f32; CORNERS_STRIDE];
            let (loss, skipped) = cell_pairs(p.neighbours(), normals, c, r as usize, &mut out);
            (out, loss, skipped)
        })
        .collect();
    let mut st = NormalRegStats::default();
    for (&r, (v, loss, skipped)) in work.iter().zip(&computed) {
        corners[CORNERS_STRIDE * r as usize..][..CORNERS_STRIDE].copy_from_slice(v);
        st.loss += loss;
        st.skipped += skipped;
    }
    st
}
