//! Grid resampling (trilinear, svox2's vertex placement).

use super::{Grid, SH_DIM};
use rayon::prelude::*;

/// Trilinear sample of all per-vertex channels of `g` at continuous grid coordinates `p`
/// (clamped into the grid; unallocated corners count as 0). Writes σ then the 27 SH values.
fn sample(g: &Grid, p: [f32; 3], out: &mut [f32; 1 + SH_DIM]) {
    let mut base = [0u32; 3];
    let mut frac = [0f32; 3];
    for i in 0..3 {
        let hi = (g.res[i] - 1) as f32;
        let q = p[i].clamp(0.0, hi);
        let l = (q.floor() as u32).min(g.res[i].saturating_sub(2));
        base[i] = l;
        frac[i] = q - l as f32;
    }
    out.fill(0.0);
    for corner in 0..8u32 {
        let (a, b, c) = (corner >> 2 & 1, corner >> 1 & 1, corner & 1);
        let v = [base[0] + a, base[1] + b, base[2] + c];
        if v.iter().zip(&g.res).any(|(&x, &r)| x >= r) {
            continue;
        }
        let link = g.links[g.slot(v[0], v[1], v[2])];
        if link < 0 {
            continue;
        }
        let w = [a, b, c]
            .iter()
            .zip(&frac)
            .map(|(&bit, &f)| if bit == 1 { f } else { 1.0 - f })
            .product::<f32>();
        let row = link as usize;
        out[0] += w * g.density[row];
        for k in 0..SH_DIM {
            out[1 + k] += w * g.sh[row * SH_DIM + k];
        }
    }
}

/// Resample `g` to `new_res`³ vertices: new vertex j sits at old coordinate
/// linspace(f − 0.5, N_old − f − 0.5, N_new)[j] with f = ½·N_old/N_new (svox2), values are
/// trilinear. Only vertices where `keep_old` (a mask over the old slots, e.g. pruned by render
/// weight and dilated) has a kept vertex among the 8 surrounding old vertices are allocated.
/// `fits` sees how many that is before their rows are allocated, and may refuse.
pub fn upsample(
    g: &Grid,
    new_res: u32,
    keep_old: &[bool],
    fits: impl FnOnce(usize) -> anyhow::Result<()>,
) -> anyhow::Result<Grid> {
    let res = [new_res; 3];
    let coord = |axis: usize, j: u32| -> f32 {
        let n_old = g.res[axis] as f32;
        let f = 0.5 * n_old / new_res as f32;
        let (lo, hi) = (f - 0.5, n_old - f - 0.5);
        if new_res == 1 {
            lo
        } else {
            lo + (hi - lo) * j as f32 / (new_res - 1) as f32
        }
    };
    // The new grid's shape; its arrays are filled below.
    let shape = Grid {
        res,
        center: g.center,
        radius: g.radius,
        links: Vec::new(),
        density: Vec::new(),
        sh: Vec::new(),
    };
    // Any kept old vertex among the 8 around new vertex `s`? Per axis, new index j lies in the
    // old cell [lo, lo + 1] (clamped into the grid), so the test is separable: OR the mask over
    // the two old indices along z, then y, then x. Only the kept slots are listed and only their
    // rows are sampled, so memory stays at the two grids' rows (a per-slot row of the whole 512³
    // grid would take 15 GB).
    let corners = |axis: usize| -> Vec<[usize; 2]> {
        let r = g.res[axis];
        (0..new_res)
            .map(|j| {
                let p = coord(axis, j).clamp(0.0, (r - 1) as f32);
                let lo = (p.floor() as u32).min(r.saturating_sub(2));
                [lo as usize, (lo + 1).min(r - 1) as usize]
            })
            .collect()
    };
    let [ox, oy, oz] = g.res.map(|r| r as usize);
    let n = new_res as usize;
    let (cx, cy, cz) = (corners(0), corners(1), corners(2));
    // Over (old x, old y, new z), then (old x, new y, new z).
    let mut along_z = vec![false; ox * oy * n];
    along_z.par_chunks_mut(n).enumerate().for_each(|(xy, out)| {
        let row = &keep_old[xy * oz..(xy + 1) * oz];
        for (o, [a, b]) in out.iter_mut().zip(&cz) {
            *o = row[*a] || row[*b];
        }
    });
    let mut along_yz = vec![false; ox * n * n];
    along_yz
        .par_chunks_mut(n * n)
        .enumerate()
        .for_each(|(x, out)| {
            for (y, [a, b]) in cy.iter().enumerate() {
                let (ra, rb) = (
                    &along_z[(x * oy + a) * n..][..n],
                    &along_z[(x * oy + b) * n..][..n],
                );
                for (o, (p, q)) in out[y * n..(y + 1) * n].iter_mut().zip(ra.iter().zip(rb)) {
                    *o = *p || *q;
                }
            }
        });
    drop(along_z);
    let kept: Vec<usize> = cx
        .par_iter()
        .enumerate()
        .flat_map_iter(|(x, [a, b])| {
            let (pa, pb) = (
                &along_yz[a * n * n..][..n * n],
                &along_yz[b * n * n..][..n * n],
            );
            (0..n * n)
                .filter(move |&i| pa[i] || pb[i])
                .map(move |i| x * n * n + i)
        })
        .collect();
    drop(along_yz);
    fits(kept.len())?;
    let position = |s: usize| {
        let v = shape.vertex(s);
        [coord(0, v[0]), coord(1, v[1]), coord(2, v[2])]
    };
    let mut density = vec![0.0; kept.len()];
    let mut sh = vec![0.0; kept.len() * SH_DIM];
    density
        .par_iter_mut()
        .zip(sh.par_chunks_mut(SH_DIM))
        .zip(&kept)
        .for_each(|((d, sh), &s)| {
            let mut vals = [0f32; 1 + SH_DIM];
            sample(g, position(s), &mut vals);
            *d = vals[0];
            sh.copy_from_slice(&vals[1..]);
        });
    let mut links = vec![-1; shape.slots()];
    for (row, &s) in kept.iter().enumerate() {
        links[s] = row as i32;
    }
    Ok(Grid {
        links,
        density,
        sh,
        ..shape
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::grid::mask::tests::random_mask;

    #[test]
    fn upsampling_keeps_the_vertices_whose_old_cell_has_a_kept_corner() {
        // Against the definition, new vertex by new vertex: its position in old coordinates
        // (clamped), the old cell holding it, any of the cell's 8 corners kept. Old grids of
        // odd and even sizes, up by non-integer factors and down.
        for (old, new_res, seed) in [(6u32, 16u32, 4u64), (7, 10, 5), (9, 5, 6), (8, 16, 7)] {
            let mut g = Grid::sphere(old, [0.0; 3], [1.0; 3], 10.0, 0.0);
            g.density
                .iter_mut()
                .enumerate()
                .for_each(|(i, d)| *d = i as f32);
            let keep = random_mask(g.res, 0.05, seed);
            let up = upsample(&g, new_res, &keep, |_| Ok(())).unwrap();
            let f = 0.5 * old as f32 / new_res as f32;
            let step = (old as f32 - 2.0 * f) / (new_res - 1) as f32;
            let mut rows = 0;
            for s in 0..up.slots() {
                let v = up.vertex(s);
                let cell = v.map(|j| {
                    let p = (f - 0.5 + step * j as f32).clamp(0.0, (old - 1) as f32);
                    (p.floor() as u32).min(old - 2)
                });
                let want = (0..8u32).any(|c| {
                    let o: [u32; 3] =
                        std::array::from_fn(|i| (cell[i] + (c >> (2 - i) & 1)).min(old - 1));
                    keep[g.slot(o[0], o[1], o[2])]
                });
                assert_eq!(up.links[s] >= 0, want, "{old}³ → {new_res}³ at {v:?}");
                if want {
                    assert_eq!(up.links[s], rows, "rows follow the slot order");
                    rows += 1;
                }
            }
            assert_eq!(up.allocated(), rows as usize);
        }
    }

    #[test]
    fn upsampling_asks_before_allocating_and_stops_when_refused() {
        let g = Grid::sphere(8, [0.0; 3], [1.0; 3], 10.0, 0.0);
        let mut keep = vec![false; g.slots()];
        keep[g.slot(3, 4, 5)] = true;
        let mut seen = None;
        let up = upsample(&g, 16, &keep, |n| {
            seen = Some(n);
            Ok(())
        })
        .unwrap();
        assert_eq!(seen, Some(up.allocated()));
        let e = upsample(&g, 16, &keep, |n| anyhow::bail!("{n} vertices do not fit")).unwrap_err();
        assert_eq!(format!("{e:#}"), "64 vertices do not fit");
    }

    #[test]
    fn upsampling_a_linear_field_is_exact() {
        // σ = x + 2y − z in old grid coordinates is reproduced at the new vertex positions.
        let mut g = Grid::sphere(8, [0.0; 3], [1.0; 3], 10.0, 0.0);
        for s in 0..g.slots() {
            let v = g.vertex(s);
            let row = g.links[s] as usize;
            g.density[row] = v[0] as f32 + 2.0 * v[1] as f32 - v[2] as f32;
            g.sh[row * SH_DIM + 5] = v[1] as f32;
        }
        let keep = vec![true; g.slots()];
        let up = upsample(&g, 16, &keep, |_| Ok(())).unwrap();
        assert_eq!(up.allocated(), 16 * 16 * 16);
        let f = 0.5 * 8.0 / 16.0;
        let step = (8.0 - 2.0 * f) / 15.0;
        for s in 0..up.slots() {
            let v = up.vertex(s);
            let p = v.map(|j| f - 0.5 + step * j as f32);
            if p.iter().any(|&x| !(0.0..=7.0).contains(&x)) {
                continue; // outside the old vertices values are clamped, not extrapolated
            }
            let want = p[0] + 2.0 * p[1] - p[2];
            let row = up.links[s] as usize;
            assert!((up.density[row] - want).abs() < 1e-4, "{v:?}");
            assert!((up.sh[row * SH_DIM + 5] - p[1]).abs() < 1e-4);
        }
        // Round trip of the world box: the new grid covers the same scene box.
        assert_eq!(up.center, g.center);
    }

    #[test]
    fn upsampling_allocates_only_around_kept_vertices() {
        let g = Grid::sphere(8, [0.0; 3], [1.0; 3], 10.0, 0.0);
        let mut keep = vec![false; g.slots()];
        keep[g.slot(3, 4, 5)] = true;
        let up = upsample(&g, 16, &keep, |_| Ok(())).unwrap();
        // New vertex j sits at old coordinate j/2 − 0.25: the vertices whose surrounding old
        // cell has (3, 4, 5) as a corner are x 5..=8, y 7..=10, z 9..=12 (4³ = 64).
        assert_eq!(up.allocated(), 64);
        let mut rows = Vec::new();
        for s in 0..up.slots() {
            let v = up.vertex(s);
            let inside =
                (5..=8).contains(&v[0]) && (7..=10).contains(&v[1]) && (9..=12).contains(&v[2]);
            assert_eq!(up.links[s] >= 0, inside, "{v:?}");
            if inside {
                rows.push(up.links[s]);
            }
        }
        // Rows follow the slot order, one per allocated vertex.
        assert_eq!(rows, (0..64).collect::<Vec<i32>>());
    }
}
