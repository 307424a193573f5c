//! Twins of the stage-2 per-vertex regularisers (method.md §3.4): `glsl/surface_opacity_reg.comp`
//! (Lα) and `glsl/surface_normal_reg.comp` (Ln1 + Ln2), same formulation and operation order as
//! the kernels; and the [`TvChunk`]s with which `glsl/tv.comp` (twin [`super::tv`]) computes Lδ
//! and TVα. Each function ADDS its gradient and flags every vertex it gives a gradient in
//! `touched` (the twin of step.glsl's `touch`).

use super::atomic::{add, as_atomic, as_atomic_u32};
use super::step::{touch_mask, TOUCH_DELTA, TOUCH_OPACITY};
use super::TvChunk;
use rayon::prelude::*;
use std::sync::atomic::AtomicU32;

/// Lα over a chunk of allocated vertex rows: rows (start + i) mod rows for i < min(count, rows)
/// (the kernel wraps; `rows` is the allocated vertex count).
#[derive(Clone, Copy, Debug)]
pub struct OpacityChunk {
    pub rows: u32,
    pub start: u32,
    pub count: u32,
    pub lambda: f32,
}

/// Lα = λ·Σ log σα over the chunk's rows with σα > 0; grad += λ/max(σα, 1e-8) there (and those
/// rows' σα group touched). Returns Lα (f64 sum of the f32 terms λ·ln σα).
pub fn surface_opacity_reg(
    opacity: &[f32],
    grad: &mut [f32],
    touched: &mut [u32],
    c: &OpacityChunk,
) -> f64 {
    let rows = c.rows as usize;
    if rows == 0 {
        return 0.0;
    }
    let n = (c.count as usize).min(rows);
    let start = c.start as usize % rows;
    let mut loss = 0.0f64;
    for i in 0..n {
        let r = (start + i) % rows;
        let a = opacity[r];
        if a > 0.0 {
            loss += (c.lambda * a.ln()) as f64;
            grad[r] += c.lambda / a.max(1e-8);
            touched[r] |= TOUCH_OPACITY;
        }
    }
    loss
}

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
}

/// What one call of [`surface_normal_reg`] found.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NormalRegStats {
    /// The loss (f64 sum of the per-cell f32 terms).
    pub loss: f64,
    /// Pairs skipped because a normal was tiny (|n|² ≤ [`TINY_NORMAL2`]).
    pub skipped: u32,
}

/// Pairs where a cell's unnormalised normal has |n|² at most this are skipped (no direction).
pub const TINY_NORMAL2: f32 = 1e-12;

/// A cell's state: missing (outside the grid or a corner unallocated), tiny normal, or a
/// direction.
#[derive(Clone, Copy, PartialEq)]
enum Cell {
    Missing,
    Tiny([i32; 8]),
    Valid([i32; 8], [f32; 3]),
}

fn slot_vertex(res: [u32; 3], s: usize) -> [usize; 3] {
    let (ry, rz) = (res[1] as usize, res[2] as usize);
    [s / (ry * rz), (s / rz) % ry, s % rz]
}

fn axis_stride(res: [u32; 3], a: usize) -> usize {
    [(res[1] * res[2]) as usize, res[2] as usize, 1][a]
}

/// The corner links of the cell at slot s, vertex v, if it exists.
fn cell_links(links: &[i32], res: [u32; 3], s: usize, v: [usize; 3]) -> Option<[i32; 8]> {
    if (0..3).any(|a| v[a] + 1 >= res[a] as usize) {
        return None;
    }
    let mut l = [0i32; 8];
    for (k, lk) in l.iter_mut().enumerate() {
        let cs =
            s + ((k >> 2) & 1) * axis_stride(res, 0) + ((k >> 1) & 1) * res[2] as usize + (k & 1);
        *lk = links[cs];
        if *lk < 0 {
            return None;
        }
    }
    Some(l)
}

/// Twin of the kernel's `cell_normal`.
fn cell_normal(links: &[i32], delta: &[f32], res: [u32; 3], s: usize, v: [usize; 3]) -> Cell {
    let Some(l) = cell_links(links, res, s, v) else {
        return Cell::Missing;
    };
    let d = l.map(|x| delta[x as usize]);
    let mx = ((d[4] + d[5]) + (d[6] + d[7])) - ((d[0] + d[1]) + (d[2] + d[3]));
    let my = ((d[2] + d[3]) + (d[6] + d[7])) - ((d[0] + d[1]) + (d[4] + d[5]));
    let mz = ((d[1] + d[3]) + (d[5] + d[7])) - ((d[0] + d[2]) + (d[4] + d[6]));
    let n = [mx * 0.25, my * 0.25, mz * 0.25];
    let n2 = (n[0] * n[0] + n[1] * n[1]) + n[2] * n[2];
    if n2 <= TINY_NORMAL2 {
        Cell::Tiny(l)
    } else {
        Cell::Valid(l, n)
    }
}

/// Number of existing forward neighbours of the cell of row slot s (0 if it does not exist).
fn existing_neighbours(links: &[i32], res: [u32; 3], s: usize) -> u32 {
    let v = slot_vertex(res, s);
    if cell_links(links, res, s, v).is_none() {
        return 0;
    }
    (0..3)
        .filter(|&a| {
            let mut va = v;
            va[a] += 1;
            cell_links(links, res, s + axis_stride(res, a), va).is_some()
        })
        .count() as u32
}

/// Per-grid prefix count of the rows whose cell has an existing forward neighbour; gives the
/// denominator M of any row chunk. Depends on the allocation only: build it once per grid.
pub struct NormalPrefix {
    res: [u32; 3],
    /// prefix[r] = number of such rows below r (rows + 1 entries).
    prefix: Vec<u32>,
}

impl NormalPrefix {
    pub fn new(links: &[i32], row_slot: &[u32], res: [u32; 3]) -> NormalPrefix {
        let has: Vec<u32> = row_slot
            .par_iter()
            .map(|&s| (existing_neighbours(links, res, s as usize) > 0) as u32)
            .collect();
        let mut prefix = Vec::with_capacity(has.len() + 1);
        prefix.push(0);
        for h in has {
            prefix.push(prefix.last().copied().unwrap_or(0) + h);
        }
        NormalPrefix { res, prefix }
    }

    /// The number of allocated rows.
    pub fn rows(&self) -> u32 {
        (self.prefix.len() - 1) as u32
    }

    /// The chunk of rows (start + i) mod rows, i < min(count, rows), with its M.
    /// The chunk of `count` rows from `start`, flagging δ touched (set `touch` to change that).
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
        NormalChunk {
            res: self.res,
            rows,
            start,
            count,
            cells,
            lambda1,
            lambda2,
            touch: TOUCH_DELTA,
        }
    }
}

fn norm3(n: [f32; 3]) -> f32 {
    ((n[0] * n[0] + n[1] * n[1]) + n[2] * n[2]).sqrt()
}

/// ∂L/∂n from ∂L/∂N for N = n/|n|: (g − N·(N·g))/|n|.
fn unnormalise_grad(n: [f32; 3], g: [f32; 3]) -> [f32; 3] {
    let r = norm3(n);
    let nn = n.map(|x| x / r);
    let p = (nn[0] * g[0] + nn[1] * g[1]) + nn[2] * g[2];
    std::array::from_fn(|i| (g[i] - nn[i] * p) / r)
}

/// ∂n/∂δ_k contracted with gn: Σ_a gn_a·(bit_a(k) ? +¼ : −¼).
fn corner_grad(k: usize, gn: [f32; 3]) -> f32 {
    let q = gn.map(|x| x * 0.25);
    let s = |bit: usize, x: f32| if bit != 0 { x } else { -x };
    (s((k >> 2) & 1, q[0]) + s((k >> 1) & 1, q[1])) + s(k & 1, q[2])
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

/// Twin of the kernel's `cell_term` for chunk cell i: adds its gradients, returns its loss share
/// and skipped pairs.
fn cell_term(
    links: &[i32],
    row_slot: &[u32],
    delta: &[f32],
    c: &NormalChunk,
    i: usize,
    grad: &[AtomicU32],
    flags: &[AtomicU32],
) -> (f64, u32) {
    let rows = c.rows as usize;
    let s = row_slot[(c.start as usize % rows + i) % rows] as usize;
    let v = slot_vertex(c.res, s);
    let own = cell_normal(links, delta, c.res, s, v);
    if own == Cell::Missing {
        return (0.0, 0);
    }
    let mut k = 0u32;
    let mut skipped = 0u32;
    let nb: [Option<([i32; 8], [f32; 3])>; 3] = std::array::from_fn(|a| {
        let mut va = v;
        va[a] += 1;
        let cn = cell_normal(links, delta, c.res, s + axis_stride(c.res, a), va);
        if cn != Cell::Missing {
            k += 1;
        }
        match (cn, own) {
            (Cell::Valid(l, n), Cell::Valid(..)) => Some((l, n)),
            (Cell::Missing, _) => None,
            _ => {
                skipped += 1;
                None
            }
        }
    });
    let Cell::Valid(lc, nc) = own else {
        return (0.0, skipped);
    };
    if nb.iter().all(Option::is_none) {
        return (0.0, skipped);
    }
    let w = 1.0 / (k as f32 * c.cells as f32);
    let rc = norm3(nc);
    let n_c = nc.map(|x| x / rc);
    let mut gc = [0f32; 3];
    let mut g = [0f32; 8];
    let mut lsum = 0f32;
    for (a, nb) in nb.iter().enumerate() {
        let Some((ln, nn)) = nb else { continue };
        let r = norm3(*nn);
        let n_n = nn.map(|x| x / r);
        let d: [f32; 3] = std::array::from_fn(|j| n_c[j] - n_n[j]);
        let l1 = (d[0].abs() + d[1].abs()) + d[2].abs();
        let l2 = (d[0] * d[0] + d[1] * d[1]) + d[2] * d[2];
        lsum += c.lambda1 * l1 + c.lambda2 * l2;
        let gn: [f32; 3] =
            std::array::from_fn(|j| w * (c.lambda1 * sign0(d[j]) + (2.0 * c.lambda2) * d[j]));
        for j in 0..3 {
            gc[j] += gn[j];
        }
        let gnn = unnormalise_grad(*nn, gn.map(|x| -x));
        let bit = 4usize >> a;
        for kk in 0..8 {
            let gk = corner_grad(kk, gnn);
            if kk & bit == 0 {
                g[kk | bit] += gk;
            } else {
                add(&grad[ln[kk] as usize], gk);
                touch_mask(flags, ln[kk] as usize, c.touch);
            }
        }
    }
    let gnc = unnormalise_grad(nc, gc);
    for kk in 0..8 {
        add(&grad[lc[kk] as usize], g[kk] + corner_grad(kk, gnc));
        touch_mask(flags, lc[kk] as usize, c.touch);
    }
    ((w * lsum) as f64, skipped)
}

/// Ln1 + Ln2 (see `glsl/surface_normal_reg.comp` for the definition): grad += ∂loss/∂δ by atomic
/// adds (as the kernel), the corners of the cells of every kept pair touched.
pub fn surface_normal_reg(
    links: &[i32],
    row_slot: &[u32],
    delta: &[f32],
    grad: &mut [f32],
    touched: &mut [u32],
    c: &NormalChunk,
) -> NormalRegStats {
    let n = (c.count as usize).min(c.rows as usize);
    let grad = as_atomic(grad);
    let flags = as_atomic_u32(touched);
    let (loss, skipped) = (0..n)
        .into_par_iter()
        .map(|i| cell_term(links, row_slot, delta, c, i, grad, flags))
        .reduce(|| (0.0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    NormalRegStats { loss, skipped }
}

/// The slot of each allocated vertex row (the inverse of `links`), for [`surface_normal_reg`].
pub fn row_slots(links: &[i32], rows: usize) -> Vec<u32> {
    let mut out = vec![0u32; rows];
    for (s, &l) in links.iter().enumerate() {
        if l >= 0 {
            out[l as usize] = s as u32;
        }
    }
    out
}

/// The [`TvChunk`] of Lδ (method.md §3.4): TV on δ (1 channel) over all slots, forward
/// differences scaled by κ = N/256 (N = the largest resolution, the grid's N for cubic grids),
/// mean over the `allocated` vertices: loss_v = κ·√(|d|² + 1e-9) = √(κ²|d|² + κ²·1e-9), which
/// is the definition √(κ²|d|² + 1e-9) up to the ε, so scale = λ·κ/allocated.
pub fn delta_tv_chunk(res: [u32; 3], allocated: usize, lambda: f32) -> TvChunk {
    let kappa = res.iter().copied().max().unwrap_or(0) as f32 / 256.0;
    TvChunk {
        res,
        start: 0,
        count: res.iter().product(),
        channels: 1,
        scale: lambda * kappa / allocated.max(1) as f32,
        // Every vertex gets a δ gradient: the backends update δ densely instead of flagging it.
        touch: 0,
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
