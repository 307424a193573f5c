//! Twin of `glsl/extract_points.comp`: dense virtual rays through every listed cell (R² per axis,
//! direction +axis, from the entry face), the first crossing of each level per ray (optionally the
//! first whose trilerped opacity passes the threshold). Same loops and formulas as the kernel;
//! rayon over the (cell, axis) invocations. The kernel emits points in atomic-counter order, this
//! twin in invocation order: compare them after sorting by [`ExtractPoint::key`].

use crate::abi::extract::{ExtractInput, ExtractPoint};
use crate::math::cubic::{cell_cubic, level_ends, solve_crossings};
use crate::math::trilerp::{trilerp, trilerp_grad};
use rayon::prelude::*;

/// Lattice coordinate j / (R − 1) of the ray origins (0.5 when R = 1).
#[inline]
pub fn lattice(j: u32, r: u32) -> f32 {
    if r <= 1 {
        0.5
    } else {
        j as f32 / (r - 1) as f32
    }
}

/// The points of invocation (cell `ci`, `axis`), in the kernel's loop order.
fn invocation(inp: &ExtractInput, ci: usize, axis: u32, out: &mut Vec<ExtractPoint>) {
    let cell = inp.cells[ci];
    let yz = inp.res[1] * inp.res[2];
    let mut c = [0f32; 8];
    let mut a = [0f32; 8];
    let (mut cmin, mut cmax) = (f32::MAX, -f32::MAX);
    for k in 0..8u32 {
        let slot = cell + (k >> 2) * yz + ((k >> 1) & 1) * inp.res[2] + (k & 1);
        let row = inp.links[slot as usize] as usize;
        c[k as usize] = inp.field[row];
        if let Some(op) = inp.opacity {
            a[k as usize] = op[row];
        }
        cmin = cmin.min(c[k as usize]);
        cmax = cmax.max(c[k as usize]);
    }
    let d = [0, 1, 2].map(|k| if k == axis { 1.0f32 } else { 0.0 });
    let r = inp.rays_per_axis;
    for (l, &tau) in inp.levels.iter().enumerate() {
        if !(cmin <= tau && tau <= cmax) {
            continue;
        }
        for ju in 0..r {
            for jv in 0..r {
                let (u, v) = (lattice(ju, r), lattice(jv, r));
                let o = match axis {
                    0 => [0.0, u, v],
                    1 => [v, 0.0, u],
                    _ => [u, v, 0.0],
                };
                let x = solve_crossings(
                    cell_cubic(&c, o, d),
                    level_ends(&c, o, d, 1.0, tau),
                    1.0,
                    0.0,
                );
                for (s, _) in x.iter() {
                    let p = [0, 1, 2].map(|k| s.mul_add(d[k], o[k]));
                    let mut alpha = 1.0;
                    if inp.opacity.is_some() {
                        let sa = trilerp(&a, p);
                        if !(sa >= inp.min_opacity) {
                            continue;
                        }
                        alpha = 1.0 - (-sa.max(0.0)).exp();
                    }
                    out.push(ExtractPoint {
                        local: p,
                        grad: trilerp_grad(&c, p).1,
                        alpha,
                        cell,
                        level: l as u32,
                        ray: axis * r * r + ju * r + jv,
                    });
                    break;
                }
            }
        }
    }
}

/// Every point the kernel would emit, in (cell, axis) invocation order.
pub fn extract_points(inp: &ExtractInput) -> Vec<ExtractPoint> {
    (0..3 * inp.cells.len())
        .into_par_iter()
        .fold(Vec::new, |mut out, i| {
            invocation(inp, i / 3, (i % 3) as u32, &mut out);
            out
        })
        .reduce(Vec::new, |mut a, mut b| {
            a.append(&mut b);
            a
        })
}
