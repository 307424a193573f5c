//! Greedy radius thinning (method.md §4): visit the points in order, keep a point unless an
//! earlier kept point lies within the radius, and drop every point within the radius of a kept
//! one. Afterwards no two kept points are within the radius (distance ≤ r) of each other and every
//! dropped point is within the radius of a kept point.
//!
//! Two exact strategies, picked by the neighbourhood size measured on a sample of points:
//! - few neighbours (the usual radius, about the point spacing): each point's earlier
//!   neighbours are found in parallel (one k-d tree query per point, [`crate::math::knn::PointIndex`]) and
//!   one sequential pass over those short lists makes the decisions in order;
//! - many (a radius far above the spacing, where those lists make the cost quadratic): the kept
//!   points are held in a hash grid of cells one radius wide, and each decision looks at the kept
//!   points of 27 cells. Kept points are more than a radius apart, so a cell holds a bounded
//!   number of them: O(n) at any radius.

use crate::math::knn::{to_f64, PointIndex};
use anyhow::Result;
use rayon::prelude::*;
use std::collections::HashMap;

/// Points per rayon task in the neighbour-list pass.
const CHUNK: usize = 16384;
/// Points sampled to measure the mean neighbourhood size.
const SAMPLES: usize = 256;
/// Mean neighbours per point above which the hash grid is used: 27 cell look-ups per point
/// cost about as much as a list this long.
const DENSE_NEIGHBOURS: f64 = 64.0;

/// Indices of the points kept by greedy thinning with `radius`, in input order. `radius ≤ 0`
/// keeps every point.
pub fn thin(points: &[[f32; 3]], radius: f64) -> Result<Vec<usize>> {
    if points.is_empty() || radius.is_nan() || radius <= 0.0 {
        return Ok((0..points.len()).collect());
    }
    let index = PointIndex::new(points)?;
    let step = (points.len() / SAMPLES).max(1);
    let sampled: Vec<usize> = (0..points.len()).step_by(step).collect();
    let cap = std::num::NonZeroUsize::new(4 * DENSE_NEIGHBOURS as usize).expect("non-zero");
    let mean = sampled
        .par_iter()
        .map(|&i| index.count_within(&to_f64(&points[i]), radius, cap) as f64)
        .sum::<f64>()
        / sampled.len() as f64;
    Ok(if mean > DENSE_NEIGHBOURS {
        thin_hash_grid(points, radius)
    } else {
        thin_neighbour_lists(points, &index, radius)
    })
}

/// The greedy from each point's earlier neighbours, found in parallel.
fn thin_neighbour_lists(points: &[[f32; 3]], index: &PointIndex, radius: f64) -> Vec<usize> {
    // Per chunk: the earlier neighbours of its points, concatenated, and where each point's ends.
    let chunks: Vec<(Vec<u32>, Vec<u32>)> = points
        .par_chunks(CHUNK)
        .enumerate()
        .map(|(c, chunk)| {
            let mut ends = Vec::with_capacity(chunk.len());
            let mut earlier = Vec::new();
            for (k, p) in chunk.iter().enumerate() {
                let i = c * CHUNK + k;
                let near = index.within(&to_f64(p), radius);
                earlier.extend(near.into_iter().filter(|&j| j < i).map(|j| j as u32));
                ends.push(earlier.len() as u32);
            }
            (ends, earlier)
        })
        .collect();
    let mut is_kept = vec![false; points.len()];
    let mut kept = Vec::new();
    let mut i = 0;
    for (ends, earlier) in &chunks {
        let mut start = 0;
        for &end in ends {
            if !earlier[start..end as usize]
                .iter()
                .any(|&j| is_kept[j as usize])
            {
                is_kept[i] = true;
                kept.push(i);
            }
            start = end as usize;
            i += 1;
        }
    }
    kept
}

/// The greedy with the kept points in a hash grid of cells one radius wide.
fn thin_hash_grid(points: &[[f32; 3]], radius: f64) -> Vec<usize> {
    let r2 = radius * radius;
    // Coordinates beyond i64 saturate into the same edge cell: still compared exactly.
    let cell = |p: &[f64; 3]| p.map(|v| (v / radius).floor() as i64);
    let mut kept_in: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
    let mut kept = Vec::new();
    for (i, p) in points.iter().enumerate() {
        let q = to_f64(p);
        let c = cell(&q);
        let mut near = false;
        'cells: for dx in -1..=1i64 {
            for dy in -1..=1i64 {
                for dz in -1..=1i64 {
                    let key = [
                        c[0].saturating_add(dx),
                        c[1].saturating_add(dy),
                        c[2].saturating_add(dz),
                    ];
                    let Some(list) = kept_in.get(&key) else {
                        continue;
                    };
                    if list.iter().any(|&j| {
                        let o = to_f64(&points[j as usize]);
                        let d = [q[0] - o[0], q[1] - o[1], q[2] - o[2]];
                        d[0] * d[0] + d[1] * d[1] + d[2] * d[2] <= r2
                    }) {
                        near = true;
                        break 'cells;
                    }
                }
            }
        }
        if !near {
            kept_in.entry(c).or_default().push(i as u32);
            kept.push(i);
        }
    }
    kept
}

/// Thinning per level, then on the union (method.md §4). `level[i]` is point i's level index
/// (< `n_levels`). Returns the kept indices, grouped by level in level order and in input order
/// within a level.
pub fn thin_levels(
    points: &[[f32; 3]],
    level: &[u32],
    n_levels: usize,
    radius: f64,
) -> Result<Vec<usize>> {
    anyhow::ensure!(
        level.len() == points.len(),
        "{} level indices for {} points",
        level.len(),
        points.len()
    );
    if let Some(&bad) = level.iter().find(|&&l| l as usize >= n_levels) {
        anyhow::bail!("level index {bad} ≥ the {n_levels} levels");
    }
    let mut by_level: Vec<Vec<usize>> = vec![Vec::new(); n_levels];
    for (i, &l) in level.iter().enumerate() {
        by_level[l as usize].push(i);
    }
    let per_level: Vec<Vec<usize>> = by_level
        .par_iter()
        .map(|idx| {
            let pts: Vec<[f32; 3]> = idx.iter().map(|&i| points[i]).collect();
            Ok(thin(&pts, radius)?.into_iter().map(|k| idx[k]).collect())
        })
        .collect::<Result<_>>()?;
    let union: Vec<usize> = per_level.into_iter().flatten().collect();
    let pts: Vec<[f32; 3]> = union.iter().map(|&i| points[i]).collect();
    Ok(thin(&pts, radius)?.into_iter().map(|k| union[k]).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// The greedy as stated: visit in order, keep a point not yet dropped, drop its neighbours.
    fn sequential(points: &[[f32; 3]], radius: f64) -> Vec<usize> {
        let index = PointIndex::new(points).unwrap();
        let mut dropped = vec![false; points.len()];
        let mut kept = Vec::new();
        for (i, p) in points.iter().enumerate() {
            if !dropped[i] {
                kept.push(i);
                for j in index.within(&to_f64(p), radius) {
                    dropped[j] = true;
                }
            }
        }
        kept
    }

    #[test]
    fn both_strategies_keep_what_the_sequential_greedy_keeps() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(11);
        // Several chunks of points in clusters (chains of near neighbours, where the order of
        // the decisions matters), with exact duplicates and points at the radius from a centre
        // (just inside or outside it after f32 rounding).
        let radius = 0.01;
        let mut pts: Vec<[f32; 3]> = Vec::new();
        while pts.len() < 3 * CHUNK + 777 {
            let c: [f32; 3] = std::array::from_fn(|_| rng.random_range(-1.0f32..1.0));
            for _ in 0..rng.random_range(1..12) {
                let p = c.map(|x| x + rng.random_range(-0.015f32..0.015));
                pts.push(p);
                if rng.random_bool(0.05) {
                    pts.push(p);
                }
            }
            pts.push([c[0] + radius as f32, c[1], c[2]]);
        }
        let kept = thin(&pts, radius).unwrap();
        assert!(
            kept.len() < pts.len() * 9 / 10,
            "{} of {}",
            kept.len(),
            pts.len()
        );
        let want = sequential(&pts, radius);
        assert_eq!(kept, want);
        // Both strategies, whichever `thin` picked here.
        let index = PointIndex::new(&pts).unwrap();
        assert_eq!(thin_neighbour_lists(&pts, &index, radius), want);
        assert_eq!(thin_hash_grid(&pts, radius), want);
    }

    #[test]
    fn a_large_radius_stays_fast_and_exact() {
        // 130k points in a unit cube at radius 0.5: each point has ~40 % of the cloud as
        // neighbours, which took 23 s with a neighbour list per point.
        let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
        let pts: Vec<[f32; 3]> = (0..130_000)
            .map(|_| std::array::from_fn(|_| rng.random_range(0.0f32..1.0)))
            .collect();
        let t = std::time::Instant::now();
        let kept = thin(&pts, 0.5).unwrap();
        assert!(t.elapsed().as_secs_f64() < 2.0, "{:?}", t.elapsed());
        assert!(kept.len() < 100, "{} kept", kept.len());
        // The stated greedy queries only the kept points, so it is quick here too.
        assert_eq!(kept, sequential(&pts, 0.5));
    }
}
