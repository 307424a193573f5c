//! Boolean vertex masks over a grid's slots (x-major, z fastest): box operations done as
//! separable one-axis passes, an x-plane per task. A 3×3×3 dilation is three 3-tap passes
//! instead of 27 reads per slot, which matters on 512³ grids (134 M slots).

use rayon::prelude::*;

/// How a pass combines a slot's neighbours along one axis.
#[derive(Clone, Copy, PartialEq)]
enum Combine {
    /// Any neighbour set; neighbours outside the grid count as unset.
    Any,
    /// Every neighbour set; a neighbour outside the grid makes the slot unset.
    All,
}

/// One axis: `out[k] = combine(src[k + o] for o in offsets)` along `axis` of a `res` grid.
fn pass(res: [usize; 3], src: &[bool], axis: usize, offsets: &[isize], how: Combine) -> Vec<bool> {
    let [rx, ry, rz] = res;
    let plane = ry * rz;
    let all = how == Combine::All;
    let apply = |out: &mut [bool], s: &[bool]| {
        if all {
            out.iter_mut().zip(s).for_each(|(o, &v)| *o &= v);
        } else {
            out.iter_mut().zip(s).for_each(|(o, &v)| *o |= v);
        }
    };
    // Rows of `len` along the axis (planes along x, z-rows along y): row i of `src` into `out`.
    let rows = |out: &mut [bool], src: &[bool], i: usize, n: usize, len: usize| {
        for &o in offsets {
            match i.checked_add_signed(o).filter(|&j| j < n) {
                Some(j) => apply(out, &src[j * len..(j + 1) * len]),
                None if all => out.fill(false),
                None => {}
            }
        }
    };
    let mut out = vec![all; src.len()];
    match axis {
        0 => out
            .par_chunks_mut(plane)
            .enumerate()
            .for_each(|(x, o)| rows(o, src, x, rx, plane)),
        1 => out
            .par_chunks_mut(plane)
            .zip(src.par_chunks(plane))
            .for_each(|(o, s)| {
                for (y, row) in o.chunks_mut(rz).enumerate() {
                    rows(row, s, y, ry, rz);
                }
            }),
        _ => out
            .par_chunks_mut(rz)
            .zip(src.par_chunks(rz))
            .for_each(|(o, s)| {
                for &off in offsets {
                    let k = off.unsigned_abs().min(rz);
                    // Combine where the neighbour lies inside the row; `past`: where it does not.
                    let past = if off >= 0 {
                        let (inside, past) = o.split_at_mut(rz - k);
                        apply(inside, &s[k..]);
                        past
                    } else {
                        let (past, inside) = o.split_at_mut(k);
                        apply(inside, &s[..rz - k]);
                        past
                    };
                    if all {
                        past.fill(false);
                    }
                }
            }),
    }
    out
}

/// The mask after one pass per axis with the same offsets.
fn separable(res: [u32; 3], mask: &[bool], offsets: &[isize], how: Combine) -> Vec<bool> {
    let res = res.map(|r| r as usize);
    assert_eq!(
        mask.len(),
        res.iter().product::<usize>(),
        "mask does not match the grid"
    );
    let x = pass(res, mask, 0, offsets, how);
    let y = pass(res, &x, 1, offsets, how);
    pass(res, &y, 2, offsets, how)
}

/// Dilate a vertex mask over the 26-neighbourhood, `times` times.
pub fn dilate(res: [u32; 3], mask: &[bool], times: usize) -> Vec<bool> {
    let mut cur: Option<Vec<bool>> = None;
    for _ in 0..times {
        let src = cur.as_deref().unwrap_or(mask);
        cur = Some(separable(res, src, &[-1, 0, 1], Combine::Any));
    }
    cur.unwrap_or_else(|| mask.to_vec())
}

/// Per cell, named by its lowest corner's slot: whether all 8 corners are `allocated` and one
/// of them is `hot`; then per vertex, whether one of the (up to 8) cells it is a corner of is.
/// Slots on the grid's upper faces name no cell. Takes the masks to free them as it goes.
pub fn cells_then_corners(res: [u32; 3], allocated: Vec<bool>, hot: Vec<bool>) -> Vec<bool> {
    let mut cells = separable(res, &allocated, &[0, 1], Combine::All);
    drop(allocated);
    let warm = separable(res, &hot, &[0, 1], Combine::Any);
    drop(hot);
    cells.par_iter_mut().zip(&warm).for_each(|(c, &w)| *c &= w);
    drop(warm);
    separable(res, &cells, &[-1, 0], Combine::Any)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    #[test]
    fn dilation_grows_a_point_to_a_cube() {
        let res = [7, 7, 7];
        let mut m = vec![false; 343];
        m[(3 * 7 + 3) * 7 + 3] = true;
        let d = dilate(res, &m, 2);
        assert_eq!(d.iter().filter(|&&b| b).count(), 125);
    }

    /// A random mask over `res` with about `share` of its slots set.
    pub(crate) fn random_mask(res: [u32; 3], share: f64, seed: u64) -> Vec<bool> {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let n = res.iter().map(|&r| r as usize).product();
        (0..n).map(|_| rng.random_bool(share)).collect()
    }

    #[test]
    fn dilation_is_the_26_neighbourhood_on_every_slot() {
        // Against the definition, slot by slot, on an uneven grid with set slots on its faces.
        let res = [5u32, 7, 6];
        let [rx, ry, rz] = res.map(|r| r as i64);
        for (seed, share) in [(1, 0.03), (2, 0.1), (3, 0.0)] {
            let m = random_mask(res, share, seed);
            let want = |m: &[bool]| -> Vec<bool> {
                (0..m.len() as i64)
                    .map(|s| {
                        let (x, y, z) = (s / (ry * rz), (s / rz) % ry, s % rz);
                        (-1..=1).any(|dx| {
                            (-1..=1).any(|dy| {
                                (-1..=1).any(|dz| {
                                    let (a, b, c) = (x + dx, y + dy, z + dz);
                                    (0..rx).contains(&a)
                                        && (0..ry).contains(&b)
                                        && (0..rz).contains(&c)
                                        && m[((a * ry + b) * rz + c) as usize]
                                })
                            })
                        })
                    })
                    .collect()
            };
            assert_eq!(dilate(res, &m, 1), want(&m), "seed {seed}");
            assert_eq!(dilate(res, &m, 2), want(&want(&m)), "seed {seed}");
        }
    }

    #[test]
    fn cells_then_corners_is_the_definition_on_every_slot() {
        // A vertex is kept when some cell it is a corner of has 8 allocated corners, one of them
        // hot; checked slot by slot on an uneven grid, hot slots unallocated too.
        let res = [6u32, 5, 7];
        let [rx, ry, rz] = res.map(|r| r as usize);
        let slot = |x: usize, y: usize, z: usize| (x * ry + y) * rz + z;
        for seed in 0..4 {
            let allocated = random_mask(res, 0.85, 10 + seed);
            let hot = random_mask(res, 0.04, 20 + seed);
            let got = cells_then_corners(res, allocated.clone(), hot.clone());
            let cell_ok = |x: usize, y: usize, z: usize| {
                let corners = (0..8).map(|i| slot(x + (i >> 2 & 1), y + (i >> 1 & 1), z + (i & 1)));
                corners.clone().all(|s| allocated[s]) && corners.clone().any(|s| hot[s])
            };
            for x in 0..rx {
                for y in 0..ry {
                    for z in 0..rz {
                        let want = (x.saturating_sub(1)..=x.min(rx - 2)).any(|cx| {
                            (y.saturating_sub(1)..=y.min(ry - 2)).any(|cy| {
                                (z.saturating_sub(1)..=z.min(rz - 2)).any(|cz| cell_ok(cx, cy, cz))
                            })
                        });
                        assert_eq!(got[slot(x, y, z)], want, "seed {seed} at {:?}", (x, y, z));
                    }
                }
            }
            assert!(
                got.iter().any(|&k| k) && !got.iter().all(|&k| k),
                "seed {seed}"
            );
        }
    }
}
