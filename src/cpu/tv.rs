//! Twin of `glsl/tv.comp`: gradient of TV on a contiguous chunk of vertex slots, gathered per
//! owned element (see the kernel for the formulation).

use rayon::prelude::*;

/// Which slots and how much: TV over slots [start, start + count), loss = scale·Σ TV.
#[derive(Clone, Copy, Debug)]
pub struct TvChunk {
    pub res: [u32; 3],
    pub start: u32,
    pub count: u32,
    pub channels: u32,
    pub scale: f32,
    /// Touched-flag bits set on every vertex given a gradient (0: none; step.glsl).
    pub touch: u32,
}

fn forward_diffs(
    links: &[i32],
    data: &[f32],
    c: &TvChunk,
    s: usize,
    l: i32,
    ch: usize,
) -> [f32; 4] {
    let (ry, rz) = (c.res[1] as usize, c.res[2] as usize);
    let v = [s / (ry * rz), (s / rz) % ry, s % rz];
    let n = c.channels as usize;
    let v0 = data[l as usize * n + ch];
    let mut d = [0f32; 3];
    for a in 0..3 {
        let stride = [ry * rz, rz, 1][a];
        if v[a] + 1 < c.res[a] as usize {
            let nl = links[s + stride];
            if nl >= 0 {
                d[a] = data[nl as usize * n + ch] - v0;
            }
        }
    }
    let tv = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2] + 1e-9).sqrt();
    [d[0], d[1], d[2], tv]
}

/// The gradient entries slot `s` owns (its vertex's `channels` values), or None when it holds
/// no vertex or no TV term of the chunk involves it.
fn slot_grad(links: &[i32], data: &[f32], c: &TvChunk, s: usize) -> Option<(usize, Vec<f32>)> {
    let n = c.channels as usize;
    let (ry, rz) = (c.res[1] as usize, c.res[2] as usize);
    let (start, end) = (c.start as usize, c.start as usize + c.count as usize);
    let l = links[s];
    if l < 0 {
        return None;
    }
    let v = [s / (ry * rz), (s / rz) % ry, s % rz];
    let has_term = |a: usize| {
        let stride = [ry * rz, rz, 1][a];
        v[a] > 0 && (start..end).contains(&(s - stride)) && links[s - stride] >= 0
    };
    if s >= end && !(0..3).any(has_term) {
        return None;
    }
    let g: Vec<f32> = (0..n)
        .map(|ch| {
            let mut g = 0.0f32;
            if (start..end).contains(&s) {
                let own = forward_diffs(links, data, c, s, l, ch);
                g -= (own[0] + own[1] + own[2]) / own[3];
            }
            for a in 0..3 {
                let stride = [ry * rz, rz, 1][a];
                if v[a] == 0 {
                    continue;
                }
                let u = s - stride;
                if u < start || u >= end || links[u] < 0 {
                    continue;
                }
                let tu = forward_diffs(links, data, c, u, links[u], ch);
                g += tu[a] / tu[3];
            }
            g
        })
        .collect();
    Some((l as usize, g))
}

/// Add the owned gradients and set the chunk's touched bits.
fn apply(updates: Vec<(usize, Vec<f32>)>, grad: &mut [f32], touched: &mut [u32], c: &TvChunk) {
    let n = c.channels as usize;
    for (l, g) in updates {
        touched[l] |= c.touch;
        for (ch, gv) in g.into_iter().enumerate() {
            grad[l * n + ch] += c.scale * gv;
        }
    }
}

/// grad += ∂(scale·Σ_chunk TV)/∂data, per allocated vertex and channel; every vertex written is
/// flagged in `touched` with the chunk's bits.
pub fn tv(links: &[i32], data: &[f32], grad: &mut [f32], touched: &mut [u32], c: &TvChunk) {
    let (ry, rz) = (c.res[1] as usize, c.res[2] as usize);
    let slots = links.len();
    let span_end = (c.start as usize + c.count as usize + ry * rz).min(slots);
    let updates: Vec<_> = ((c.start as usize).min(slots)..span_end)
        .into_par_iter()
        .filter_map(|s| slot_grad(links, data, c, s))
        .collect();
    apply(updates, grad, touched, c);
}
