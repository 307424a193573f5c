//! Greedy radius thinning (method.md §4): visit the points in order, keep a point unless an
//! earlier kept point lies within the radius, and drop every point within the radius of a kept
//! one. Afterwards no two kept points are within the radius (distance ≤ r) of each other and every
//! dropped point is within the radius of a kept point. Neighbourhoods come from a k-d tree
//! ([`super::PointIndex`]), so the cost is O(n log n + Σ neighbourhood sizes), not O(n²).

use super::knn::{to_f64, PointIndex};
use anyhow::Result;
use rayon::prelude::*;

/// Points per rayon task in [`thin`]'s neighbour pass.
const CHUNK: usize = 16384;

/// Indices of the points kept by greedy thinning with `radius`, in input order. `radius ≤ 0`
/// keeps every point.
///
/// The greedy keeps point i exactly when no earlier *kept* point lies within the radius. So the
/// costly part, each point's earlier neighbours, is found in parallel (one k-d tree query per
/// point), and one sequential pass over those short lists makes the decisions in order.
pub fn thin(points: &[[f32; 3]], radius: f64) -> Result<Vec<usize>> {
    if points.is_empty() || radius.is_nan() || radius <= 0.0 {
        return Ok((0..points.len()).collect());
    }
    let index = PointIndex::new(points)?;
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
    Ok(kept)
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
    fn parallel_pass_keeps_what_the_sequential_greedy_keeps() {
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
        assert_eq!(kept, sequential(&pts, radius));
    }
}
