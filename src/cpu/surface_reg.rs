//! Twins of the stage-2 per-vertex regularisers (method.md §3.4): `glsl/surface_opacity_reg.comp`
//! (Lα) and the three passes `glsl/surface_normal_reg_{cells,pairs,gather}.comp` (Ln1 +
//! Ln2; with `glsl/lib/normal_reg.glsl`), same formulation and operation order as the kernels;
//! the [`TvChunk`] with which `glsl/tv.comp` (twin [`super::tv`]) computes TVα and the
//! [`DeltaTvChunk`] of Lδ (`glsl/surface_delta_tv.comp`). Each function ADDS its gradient; the
//! normal regularisers flag the vertices they give a gradient in `touched` (the twin of
//! step.glsl's `touch_mask`) unless RMSProp's δ rows cover them.

use super::step::{RowRange, TOUCH_DELTA, TOUCH_OPACITY};
use super::surface_delta_tv::DeltaTvChunk;
use super::TvChunk;
use rayon::prelude::*;

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

/// Lα = λ·Σ log σα over the chunk's rows with σα > 0; grad += λ/max(σα, 1e-8) there. Nothing is
/// flagged: RMSProp updates σα on every row of the chunk (`SurfaceRmsProp::opacity_rows`).
/// Returns Lα (f64 sum of the f32 terms λ·ln σα).
pub fn surface_opacity_reg(opacity: &[f32], grad: &mut [f32], c: &OpacityChunk) -> f64 {
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
fn work_rows(list: &[u32], work: (u32, u32)) -> Vec<u32> {
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

/// What one call of [`surface_normal_reg`] found.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NormalRegStats {
    /// The loss (f64 sum of the per-cell f32 terms).
    pub loss: f64,
    /// Pairs skipped because a normal was tiny (|n|² ≤ [`TINY_NORMAL2`]).
    pub skipped: u32,
}

pub use crate::abi::consts::{NBR_B, NBR_STRIDE, TINY_NORMAL2};
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

/// Pass 1, twin of `surface_normal_reg_cells`: normals[r] = (n, status + 4·k) of the cells of
/// the chunk's window (`c.cells_work`); the other rows keep what they held, as in the kernel
/// (the pairs pass reads only the window's).
pub fn normal_cells(p: &NormalPrefix, delta: &[f32], c: &NormalChunk, normals: &mut [f32]) {
    let work = work_rows(&p.cell_rows, c.cells_work);
    let computed: Vec<[f32; NORMALS_STRIDE]> = work
        .par_iter()
        .map(|&r| {
            let r = r as usize;
            let t = &p.nbr[NBR_STRIDE * r..][..NBR_STRIDE];
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
    let work = work_rows(&p.cell_rows, c.cells_work);
    let computed: Vec<([f32; CORNERS_STRIDE], f64, u32)> = work
        .par_iter()
        .map(|&r| {
            let mut out = [0f32; CORNERS_STRIDE];
            let (loss, skipped) = cell_pairs(&p.nbr, normals, c, r as usize, &mut out);
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
    let work = work_rows(&p.corner_rows, c.corners_work);
    let window = c.rows_from_start(c.window);
    let sums: Vec<Option<f32>> = work
        .par_iter()
        .map(|&r| {
            let r = r as usize;
            let nb = &p.nbr[NBR_STRIDE * r..][..NBR_STRIDE];
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
