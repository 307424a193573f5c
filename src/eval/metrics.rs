//! Chamfer distance and F-score between a predicted and a ground-truth point cloud, the Blender
//! variant of the DTU python protocol (method.md §4): d2s = distance of each predicted point to
//! its nearest GT point, s2d = of each GT point to its nearest predicted point; mean d2s and mean
//! s2d over the distances < `max_dist`; Chamfer = their mean. Precision = fraction of predicted
//! points with d2s < `threshold`, recall = fraction of GT points with s2d < `threshold`,
//! F1 = 2PR / (P + R) (0 when both are 0). Means are summed in point order (deterministic).

use super::objects::{group_errors, GroupError};
use crate::math::knn::PointIndex;
use anyhow::Result;

/// Protocol parameters.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct EvalOptions {
    /// Distances at or above this are left out of the Chamfer means (Blender units; paper 1.5).
    pub max_dist: f64,
    /// Precision/recall threshold (paper 0.01).
    pub threshold: f64,
}

impl Default for EvalOptions {
    fn default() -> Self {
        EvalOptions {
            max_dist: 1.5,
            threshold: 0.01,
        }
    }
}

/// The metrics of one evaluation. A mean over no distances is NaN (serialised as null).
#[derive(Clone, Debug, serde::Serialize)]
pub struct Metrics {
    pub n_pred: usize,
    pub n_gt: usize,
    /// Mean d2s over d2s < max_dist.
    pub mean_d2s: f64,
    /// Mean s2d over s2d < max_dist.
    pub mean_s2d: f64,
    /// (mean_d2s + mean_s2d) / 2.
    pub chamfer: f64,
    pub precision: f64,
    pub recall: f64,
    pub f1: f64,
    /// How many predicted / GT distances entered the means.
    pub d2s_used: usize,
    pub s2d_used: usize,
    pub max_dist: f64,
    pub threshold: f64,
    /// Median, 90th and 99th percentile of d2s and of s2d (where the error sits: a low median
    /// with a high mean means outliers).
    pub d2s_quantiles: [f64; 3],
    pub s2d_quantiles: [f64; 3],
    /// Per object group, when the GT cloud's objects are known ([`super::objects`]).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub objects: Vec<GroupError>,
}

/// The 50th, 90th and 99th percentiles (nearest rank; NaN for no values).
fn quantiles(d: &[f64]) -> [f64; 3] {
    if d.is_empty() {
        return [f64::NAN; 3];
    }
    let mut v = d.to_vec();
    v.sort_unstable_by(f64::total_cmp);
    [0.5, 0.9, 0.99].map(|q| v[((q * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1])
}

/// Mean of the values < `max`, and how many there were.
fn mean_below(d: &[f64], max: f64) -> (f64, usize) {
    let (mut sum, mut n) = (0.0, 0usize);
    for &x in d {
        if x < max {
            sum += x;
            n += 1;
        }
    }
    (if n == 0 { f64::NAN } else { sum / n as f64 }, n)
}

/// Fraction of the values < `t`.
fn fraction_below(d: &[f64], t: f64) -> f64 {
    d.iter().filter(|&&x| x < t).count() as f64 / d.len().max(1) as f64
}

/// The metrics from the two distance arrays (d2s: one per predicted point, s2d: one per GT point).
pub fn from_distances(d2s: &[f64], s2d: &[f64], opts: &EvalOptions) -> Metrics {
    let (mean_d2s, d2s_used) = mean_below(d2s, opts.max_dist);
    let (mean_s2d, s2d_used) = mean_below(s2d, opts.max_dist);
    let precision = fraction_below(d2s, opts.threshold);
    let recall = fraction_below(s2d, opts.threshold);
    let f1 = if precision + recall > 0.0 {
        2.0 * precision * recall / (precision + recall)
    } else {
        0.0
    };
    Metrics {
        n_pred: d2s.len(),
        n_gt: s2d.len(),
        mean_d2s,
        mean_s2d,
        chamfer: 0.5 * (mean_d2s + mean_s2d),
        precision,
        recall,
        f1,
        d2s_used,
        s2d_used,
        max_dist: opts.max_dist,
        threshold: opts.threshold,
        d2s_quantiles: quantiles(d2s),
        s2d_quantiles: quantiles(s2d),
        objects: Vec::new(),
    }
}

/// Nearest-neighbour distances both ways through k-d trees (parallel queries), then the metrics.
/// Both clouds must be non-empty.
pub fn evaluate(pred: &[[f32; 3]], gt: &[[f32; 3]], opts: &EvalOptions) -> Result<Metrics> {
    evaluate_groups(pred, gt, None, opts)
}

/// [`evaluate`], and with `groups` = (group names, group of each GT point) the per-group errors
/// in [`Metrics::objects`].
pub fn evaluate_groups(
    pred: &[[f32; 3]],
    gt: &[[f32; 3]],
    groups: Option<(&[String], &[u32])>,
    opts: &EvalOptions,
) -> Result<Metrics> {
    anyhow::ensure!(!pred.is_empty(), "the predicted point cloud is empty");
    anyhow::ensure!(!gt.is_empty(), "the ground-truth point cloud is empty");
    evaluate_indexed(pred, gt, &PointIndex::new(gt)?, groups, None, opts)
}

/// [`evaluate_groups`] with the GT cloud's k-d tree built once by the caller (`gt_index` over
/// `gt`), for scoring many predicted clouds against one ground truth. With `seen` (one flag per
/// GT point), completeness (s2d, recall) counts only the GT points it marks, e.g. those a
/// training view sees; accuracy (d2s, precision) is measured against every GT point.
pub fn evaluate_indexed(
    pred: &[[f32; 3]],
    gt: &[[f32; 3]],
    gt_index: &PointIndex,
    groups: Option<(&[String], &[u32])>,
    seen: Option<&[bool]>,
    opts: &EvalOptions,
) -> Result<Metrics> {
    anyhow::ensure!(!pred.is_empty(), "the predicted point cloud is empty");
    anyhow::ensure!(
        gt_index.len() == gt.len(),
        "a k-d tree of {} points for {} GT points",
        gt_index.len(),
        gt.len()
    );
    let ((d2s, nearest_gt), pred_index) = rayon::join(
        || gt_index.nearest_with_index(pred),
        || PointIndex::new(pred),
    );
    let mut s2d = pred_index?.nearest_distances(gt);
    if let Some(seen) = seen {
        anyhow::ensure!(
            seen.len() == gt.len(),
            "a mask of {} flags for {} GT points",
            seen.len(),
            gt.len()
        );
        // NaN marks a GT point completeness leaves out (a distance between finite points is
        // never NaN); the per-object split skips it too.
        for (d, &s) in s2d.iter_mut().zip(seen) {
            if !s {
                *d = f64::NAN;
            }
        }
    }
    let scored: Vec<f64> = s2d.iter().copied().filter(|d| !d.is_nan()).collect();
    anyhow::ensure!(!scored.is_empty(), "the mask leaves no GT point to score");
    let mut m = from_distances(&d2s, &scored, opts);
    if let Some((names, of_gt)) = groups {
        anyhow::ensure!(
            of_gt.len() == gt.len(),
            "{} group labels for {} GT points",
            of_gt.len(),
            gt.len()
        );
        m.objects = group_errors(names, of_gt, &d2s, &nearest_gt, &s2d, opts.max_dist);
    }
    Ok(m)
}
