//! Nearest-rank percentiles: of sorted values, and per axis of a point set (a box robust to stray
//! points).

/// The value at quantile `q` ∈ [0, 1] of ascending `sorted` (nearest rank); `sorted` not empty.
pub fn percentile<T: Copy>(sorted: &[T], q: f64) -> T {
    sorted[(q * (sorted.len() - 1) as f64).round() as usize]
}

/// Per axis, the `q.0` and `q.1` quantiles of `points` (not empty): a box robust to stray points.
pub fn percentile_bounds(points: &[&[f64; 3]], q: (f64, f64)) -> ([f64; 3], [f64; 3]) {
    let (mut lo, mut hi) = ([0f64; 3], [0f64; 3]);
    for a in 0..3 {
        let mut v: Vec<f64> = points.iter().map(|p| p[a]).collect();
        v.sort_by(f64::total_cmp);
        (lo[a], hi[a]) = (percentile(&v, q.0), percentile(&v, q.1));
    }
    (lo, hi)
}
