//! Greedy radius thinning (method.md §4): visit the points in order, keep a point unless an
//! earlier kept point lies within the radius, and drop every point within the radius of a kept
//! one. Afterwards no two kept points are within the radius (distance ≤ r) of each other and every
//! dropped point is within the radius of a kept point. Neighbourhoods come from a k-d tree
//! ([`super::PointIndex`]), so the cost is O(n log n + Σ neighbourhood sizes), not O(n²).

use super::knn::{to_f64, PointIndex};
use anyhow::Result;
use rayon::prelude::*;

/// Indices of the points kept by greedy thinning with `radius`, in input order. `radius ≤ 0`
/// keeps every point.
pub fn thin(points: &[[f32; 3]], radius: f64) -> Result<Vec<usize>> {
    if points.is_empty() || !(radius > 0.0) {
        return Ok((0..points.len()).collect());
    }
    let index = PointIndex::new(points)?;
    let mut dropped = vec![false; points.len()];
    let mut kept = Vec::new();
    for (i, p) in points.iter().enumerate() {
        if dropped[i] {
            continue;
        }
        kept.push(i);
        for j in index.within(&to_f64(p), radius) {
            dropped[j] = true;
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
