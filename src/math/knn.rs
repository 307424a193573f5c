//! Nearest-neighbour queries over 3-D point clouds through `kiddo`'s immutable k-d tree (f64
//! coordinates, exact queries, squared Euclidean metric), parallel over query points with rayon.

use anyhow::{ensure, Result};
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;

/// A k-d tree over a point cloud; items are indices into the cloud it was built from.
pub struct PointIndex {
    tree: ImmutableKdTree<f64, 3>,
    len: usize,
}

/// f32 point → f64 tree coordinates (exact).
pub fn to_f64(p: &[f32; 3]) -> [f64; 3] {
    [p[0] as f64, p[1] as f64, p[2] as f64]
}

impl PointIndex {
    /// Build the tree over `points` (non-empty, at most u32::MAX points).
    pub fn new(points: &[[f32; 3]]) -> Result<PointIndex> {
        ensure!(!points.is_empty(), "k-d tree over an empty point cloud");
        ensure!(
            points.len() < u32::MAX as usize,
            "{} points: the k-d tree indexes at most 2^32 − 1",
            points.len()
        );
        let coords: Vec<[f64; 3]> = points.par_iter().map(to_f64).collect();
        let tree = ImmutableKdTree::new_from_slice(&coords)
            .map_err(|e| anyhow::anyhow!("building the k-d tree: {e:?}"))?;
        Ok(PointIndex {
            tree,
            len: points.len(),
        })
    }

    /// Number of indexed points.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether the index is empty (never: construction refuses empty clouds).
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Euclidean distance from `q` to its nearest indexed point, and that point's index.
    pub fn nearest(&self, q: &[f64; 3]) -> (f64, usize) {
        let r = self
            .tree
            .query(q)
            .nearest_one::<SquaredEuclidean<f64>>()
            .execute();
        (r.distance.sqrt(), r.item as usize)
    }

    /// Nearest-neighbour distance of every query point (rayon).
    pub fn nearest_distances(&self, queries: &[[f32; 3]]) -> Vec<f64> {
        queries
            .par_iter()
            .map(|q| self.nearest(&to_f64(q)).0)
            .collect()
    }

    /// Nearest-neighbour distance of every query point and the index of that neighbour (rayon).
    pub fn nearest_with_index(&self, queries: &[[f32; 3]]) -> (Vec<f64>, Vec<usize>) {
        queries.par_iter().map(|q| self.nearest(&to_f64(q))).unzip()
    }

    /// How many indexed points lie within distance `radius` of `q` (inclusive), counting at
    /// most `cap` (the query stops there, so a large radius stays cheap).
    pub fn count_within(&self, q: &[f64; 3], radius: f64, cap: std::num::NonZeroUsize) -> usize {
        self.tree
            .query(q)
            .nearest_n::<SquaredEuclidean<f64>>(cap)
            .within(radius * radius)
            .execute()
            .len()
    }

    /// Indices of the indexed points within distance `radius` of `q` (inclusive), unsorted.
    pub fn within(&self, q: &[f64; 3], radius: f64) -> Vec<usize> {
        self.tree
            .query(q)
            .within::<SquaredEuclidean<f64>>(radius * radius)
            .unsorted()
            .execute()
            .into_iter()
            .map(|r| r.item as usize)
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn within_and_nearest_match_brute_force() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
        let pts: Vec<[f32; 3]> = (0..1200)
            .map(|_| [0; 3].map(|_| rng.random_range(-0.5f32..0.5)))
            .collect();
        let index = PointIndex::new(&pts).unwrap();
        let d = |a: &[f32; 3], b: &[f32; 3]| {
            (0..3)
                .map(|k| (a[k] as f64 - b[k] as f64).powi(2))
                .sum::<f64>()
                .sqrt()
        };
        for q in pts.iter().take(200) {
            let mut got = index.within(&to_f64(q), 0.05);
            got.sort_unstable();
            let want: Vec<usize> = (0..pts.len()).filter(|&j| d(q, &pts[j]) <= 0.05).collect();
            assert_eq!(got, want);
            for cap in [1, 3, 1000] {
                let n = index.count_within(&to_f64(q), 0.05, cap.try_into().unwrap());
                assert_eq!(n, want.len().min(cap));
            }
            let (dist, i) = index.nearest(&to_f64(&q.map(|x| x + 0.001)));
            assert!((dist - d(&q.map(|x| x + 0.001), &pts[i])).abs() < 1e-12);
        }
    }
}
