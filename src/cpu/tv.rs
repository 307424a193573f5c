//! Twin of `glsl/tv.comp`: gradient of TV on a contiguous chunk of vertex slots, gathered per
//! owned element (see the kernel for the formulation).

use crate::abi::regularisers::TvChunk;
use rayon::prelude::*;

/// The links every channel of a slot's gradient needs, read once (as the kernel does): its
/// vertex's row, its forward neighbours when it lies in the chunk, and for each backward
/// neighbour u = s − e_a in the chunk, u's row and u's forward neighbours (−1: none).
struct SlotLinks {
    row: usize,
    own: Option<[i32; 3]>,
    back: [i32; 3],
    back_fwd: [[i32; 3]; 3],
}

/// Forward neighbour links of slot `s` (vertex `v`), −1 outside the grid.
fn forward_links(links: &[i32], c: &TvChunk, s: usize, v: [usize; 3]) -> [i32; 3] {
    let (ry, rz) = (c.res[1] as usize, c.res[2] as usize);
    std::array::from_fn(|a| {
        if v[a] + 1 < c.res[a] as usize {
            links[s + [ry * rz, rz, 1][a]]
        } else {
            -1
        }
    })
}

/// Slot `s`'s links, or None when it holds no vertex or no TV term of the chunk involves it.
fn slot_links(links: &[i32], c: &TvChunk, s: usize) -> Option<SlotLinks> {
    let l = links[s];
    if l < 0 {
        return None;
    }
    let (ry, rz) = (c.res[1] as usize, c.res[2] as usize);
    let (start, end) = (c.start as usize, c.start as usize + c.count as usize);
    let v = [s / (ry * rz), (s / rz) % ry, s % rz];
    let own = (s < end).then(|| forward_links(links, c, s, v));
    let mut back = [-1i32; 3];
    let mut back_fwd = [[-1i32; 3]; 3];
    for a in 0..3 {
        let stride = [ry * rz, rz, 1][a];
        if v[a] == 0 || !(start..end).contains(&(s - stride)) {
            continue;
        }
        let u = s - stride;
        back[a] = links[u];
        if back[a] >= 0 {
            let mut vu = v;
            vu[a] -= 1;
            back_fwd[a] = forward_links(links, c, u, vu);
        }
    }
    (own.is_some() || back.iter().any(|&b| b >= 0)).then_some(SlotLinks {
        row: l as usize,
        own,
        back,
        back_fwd,
    })
}

/// Add `sign` × (the chosen forward differences / their TV norm) of every channel of the vertex
/// in row `l` with forward neighbours `n` to `g`: with `axis` None the sum of the three
/// differences (the vertex's own TV), else the one along `axis` (a backward neighbour's TV). A
/// missing neighbour's difference is 0 (its row index stands in for the read, unused).
fn add_tv_grad(
    data: &[f32],
    l: usize,
    n: &[i32; 3],
    axis: Option<usize>,
    sign: f32,
    g: &mut [f32],
) {
    let k = g.len();
    let row = |r: i32| if r >= 0 { r as usize } else { l };
    let (v0, x, y, z) = (
        &data[l * k..][..k],
        &data[row(n[0]) * k..][..k],
        &data[row(n[1]) * k..][..k],
        &data[row(n[2]) * k..][..k],
    );
    for ch in 0..k {
        let diff = |has: bool, v: f32| if has { v - v0[ch] } else { 0.0 };
        let d = [
            diff(n[0] >= 0, x[ch]),
            diff(n[1] >= 0, y[ch]),
            diff(n[2] >= 0, z[ch]),
        ];
        let tv = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2] + 1e-9).sqrt();
        let num = match axis {
            None => d[0] + d[1] + d[2],
            Some(a) => d[a],
        };
        g[ch] += sign * (num / tv);
    }
}

/// The gradient of the chunk's TV with respect to every channel of the slot's vertex, added to
/// `g` (zeros from the caller).
fn slot_grad(data: &[f32], sl: &SlotLinks, g: &mut [f32]) {
    if let Some(n) = &sl.own {
        add_tv_grad(data, sl.row, n, None, -1.0, g);
    }
    for a in 0..3 {
        if sl.back[a] >= 0 {
            add_tv_grad(data, sl.back[a] as usize, &sl.back_fwd[a], Some(a), 1.0, g);
        }
    }
}

/// Slots per parallel piece: each piece gathers its rows' gradients into one buffer.
const PIECE: usize = 4096;

/// grad += ∂(scale·Σ_chunk TV)/∂data, per allocated vertex and channel; every vertex written is
/// flagged in `touched` with the chunk's bits (none, and `touched` unread, when they are 0).
pub fn tv(links: &[i32], data: &[f32], grad: &mut [f32], touched: &mut [u32], c: &TvChunk) {
    let (ry, rz) = (c.res[1] as usize, c.res[2] as usize);
    let n = c.channels as usize;
    let slots = links.len();
    let first = (c.start as usize).min(slots);
    let span_end = (c.start as usize + c.count as usize + ry * rz).min(slots);
    // Per piece of slots: the rows given a gradient and their channels' gradients, in order.
    let pieces: Vec<(Vec<usize>, Vec<f32>)> = (first..span_end)
        .into_par_iter()
        .step_by(PIECE)
        .map(|p0| {
            let (mut rows, mut grads) = (Vec::new(), Vec::new());
            for s in p0..(p0 + PIECE).min(span_end) {
                if let Some(sl) = slot_links(links, c, s) {
                    rows.push(sl.row);
                    let at = grads.len();
                    grads.resize(at + n, 0.0);
                    slot_grad(data, &sl, &mut grads[at..]);
                }
            }
            (rows, grads)
        })
        .collect();
    for (rows, grads) in pieces {
        for (i, &l) in rows.iter().enumerate() {
            let g = &grads[i * n..(i + 1) * n];
            if c.touch != 0 {
                touched[l] |= c.touch;
            }
            for (dst, gv) in grad[l * n..(l + 1) * n].iter_mut().zip(g) {
                *dst += c.scale * gv;
            }
        }
    }
}
