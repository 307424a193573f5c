//! The foreground box of a capture without masks, found from its cameras: the object is where the
//! optical axes converge, and it extends as far as the sparse points around that point do once
//! the large planes (floor, walls) and isolated points (matching outliers) are set aside.
//!
//! 1. Convergence point: the least-squares point nearest to every optical axis, reweighted a few
//!    times (weights 1/max(miss, median miss)) so a few cameras aimed elsewhere do not pull it.
//!    Refused when the axes are (nearly) parallel or the point is behind most cameras.
//! 2. With sparse points: those within [`REGION`] × the median camera distance D of it; planes
//!    holding ≥ [`PLANE_SHARE`] of them whose inliers (within [`PLANE_TOLERANCE`]·D) spread over
//!    more than [`NEAR`]·D are found by RANSAC and removed (a floor, a wall: an object's own flat
//!    parts are smaller); of the points then within [`NEAR`]·D, those with fewer than
//!    [`MIN_NEIGHBOURS`] others within [`NEIGHBOUR_RADIUS`]·D are dropped (outliers); the box is
//!    the rest's bounds, grown by [`GROW`] of its size per side.
//! 3. Without sparse points (or too few left): the cube around the convergence point as wide as
//!    the median camera's view there (an upper bound of what the photos frame).

use super::aabb::Aabb;
use super::camera::Camera;
use crate::math::knn::{to_f64, PointIndex};
use crate::math::percentile::percentile_bounds;
use glam::{DMat3, DVec3, Vec3};
use rand::{Rng, SeedableRng};

/// Sparse points farther than this × D from the convergence point are not looked at.
pub const REGION: f64 = 1.0;
/// The object is taken to lie within this × D of the convergence point.
pub const NEAR: f64 = 0.5;
/// A plane is a floor or wall when it holds this share of the points in the region.
pub const PLANE_SHARE: f64 = 0.05;
/// A point is on a plane when closer to it than this × D.
pub const PLANE_TOLERANCE: f64 = 0.005;
/// Neighbourhood radius (× D) and count below which a point is an outlier.
pub const NEIGHBOUR_RADIUS: f64 = 0.03;
/// See [`NEIGHBOUR_RADIUS`].
pub const MIN_NEIGHBOURS: usize = 2;
/// The box grows by this share of its size on each side.
pub const GROW: f64 = 0.05;
/// Per-axis percentiles of sparse points that bound a scene (robust to stray points): the room's
/// box here, the COLMAP layout's box of the points in view.
pub const POINT_PERCENTILES: (f64, f64) = (0.01, 0.99);
/// Fewest points the box may be taken from.
const MIN_POINTS: usize = 20;
/// RANSAC draws per plane, and the most planes removed.
const RANSAC_DRAWS: usize = 400;
const MAX_PLANES: usize = 8;

/// The foreground box (dataset units) and how it was found.
#[derive(Clone, Debug, PartialEq)]
pub struct ForegroundBox {
    /// The box.
    pub bounds: Aabb,
    /// How it was found, for `inspect`.
    pub how: String,
    /// The sparse points' box ([`POINT_PERCENTILES`] per axis): the room the object stands in, for
    /// `inspect`'s advice on 360° captures (without a background model the floor and walls the
    /// views see can only be density inside the grid). `None` without enough sparse points.
    pub room: Option<Aabb>,
}

/// The foreground box of a capture from its cameras and (when it has them) sparse points;
/// `None` when the optical axes do not converge in front of the cameras.
pub fn find(cameras: &[Camera], points: &[[f64; 3]]) -> Option<ForegroundBox> {
    let (p, miss) = convergence(cameras)?;
    let dist: Vec<f64> = cameras
        .iter()
        .map(|c| (c.centre().as_dvec3() - p).length())
        .collect();
    let d = median(dist.clone());
    let at = format!(
        "optical axes of {} cameras converge at [{:.3}, {:.3}, {:.3}] (median miss {:.3}, median \
         camera distance {d:.3})",
        cameras.len(),
        p.x,
        p.y,
        p.z,
        miss
    );
    if let Some((lo, hi, how)) = from_points(p, d, points) {
        return Some(ForegroundBox {
            bounds: Aabb::new(lo.as_vec3(), hi.as_vec3()),
            how: format!("{at}; {how}"),
            room: room(points),
        });
    }
    // The half-width of the median camera's view at the convergence point.
    let half = median(
        cameras
            .iter()
            .zip(&dist)
            .map(|(c, &r)| {
                let tan_x = 0.5 * c.width as f64 / c.fx as f64;
                let tan_y = 0.5 * c.height as f64 / c.fy as f64;
                r * tan_x.min(tan_y)
            })
            .collect(),
    );
    Some(ForegroundBox {
        bounds: Aabb::new(
            (p - DVec3::splat(half)).as_vec3(),
            (p + DVec3::splat(half)).as_vec3(),
        ),
        how: format!(
            "{at}; {} sparse points to bound the object: the cube the median camera's view \
             spans there",
            if points.is_empty() { "no" } else { "too few" }
        ),
        room: room(points),
    })
}

/// The sparse points' box at [`POINT_PERCENTILES`]; `None` below [`MIN_POINTS`] finite points.
fn room(points: &[[f64; 3]]) -> Option<Aabb> {
    let finite: Vec<&[f64; 3]> = points
        .iter()
        .filter(|p| p.iter().all(|v| v.is_finite()))
        .collect();
    (finite.len() >= MIN_POINTS).then(|| {
        let (lo, hi) = percentile_bounds(&finite, POINT_PERCENTILES);
        Aabb::new(
            DVec3::from_array(lo).as_vec3(),
            DVec3::from_array(hi).as_vec3(),
        )
    })
}

/// The reweighted least-squares point nearest to the optical axes, and the median distance of
/// the axes from it.
fn convergence(cameras: &[Camera]) -> Option<(DVec3, f64)> {
    if cameras.len() < 2 {
        return None;
    }
    let axes: Vec<(DVec3, DVec3)> = cameras
        .iter()
        .map(|c| (c.centre().as_dvec3(), c.forward().as_dvec3()))
        .collect();
    let miss = |p: DVec3| -> Vec<f64> {
        axes.iter()
            .map(|(c, d)| {
                let v = p - *c;
                (v - d * v.dot(*d)).length()
            })
            .collect()
    };
    let mut weights = vec![1.0; axes.len()];
    let mut p = DVec3::ZERO;
    for _ in 0..5 {
        let (mut a, mut b) = (DMat3::ZERO, DVec3::ZERO);
        for ((c, d), w) in axes.iter().zip(&weights) {
            let m = DMat3::IDENTITY - DMat3::from_cols(*d * d.x, *d * d.y, *d * d.z);
            a += m * *w;
            b += m * *c * *w;
        }
        let scale = a.x_axis.x + a.y_axis.y + a.z_axis.z;
        // Nearly parallel axes leave the system (close to) singular (a NaN fails too).
        let det = a.determinant();
        if det.is_nan() || det <= 1e-6 * (scale / 3.0).powi(3) {
            return None;
        }
        p = a.inverse() * b;
        let m = miss(p);
        let floor = median(m.clone()).max(1e-9);
        weights = m.iter().map(|&e| 1.0 / e.max(floor)).collect();
    }
    let in_front = axes.iter().filter(|(c, d)| (p - *c).dot(*d) > 0.0).count();
    (p.is_finite() && 2 * in_front > axes.len()).then(|| (p, median(miss(p))))
}

/// The box of the sparse points that make the object (module documentation, step 2), and how
/// many were set aside; `None` when too few are left.
fn from_points(p: DVec3, d: f64, points: &[[f64; 3]]) -> Option<(DVec3, DVec3, String)> {
    let mut region: Vec<DVec3> = points
        .iter()
        .map(|q| DVec3::from_array(*q))
        .filter(|q| q.is_finite() && (*q - p).length() <= REGION * d)
        .collect();
    let in_region = region.len();
    if in_region < MIN_POINTS {
        return None;
    }
    let mut rng = rand_pcg::Pcg64::seed_from_u64(0x5eed);
    let tolerance = PLANE_TOLERANCE * d;
    let min_inliers = ((PLANE_SHARE * in_region as f64).ceil() as usize).max(3);
    let mut planes = 0;
    let mut on_planes = 0;
    while planes < MAX_PLANES && region.len() >= min_inliers {
        let Some((n, o)) = best_plane(&region, tolerance, &mut rng) else {
            break;
        };
        let on = |q: &DVec3| (*q - o).dot(n).abs() <= tolerance;
        let inliers: Vec<DVec3> = region.iter().copied().filter(on).collect();
        if inliers.len() < min_inliers || spread(&inliers) <= NEAR * d {
            break; // the largest plane left is an object's own face, or too small to matter
        }
        on_planes += inliers.len();
        region.retain(|q| !on(q));
        planes += 1;
    }
    let near: Vec<[f32; 3]> = region
        .iter()
        .filter(|q| (**q - p).length() <= NEAR * d)
        .map(|q| q.as_vec3().to_array())
        .collect();
    if near.len() < MIN_POINTS {
        return None;
    }
    let index = PointIndex::new(&near).ok()?;
    let cap = std::num::NonZeroUsize::new(MIN_NEIGHBOURS + 1)?;
    let radius = NEIGHBOUR_RADIUS * d;
    let kept: Vec<DVec3> = near
        .iter()
        .filter(|q| {
            // The point itself is within the radius too.
            let q64 = to_f64(q);
            index.count_within(&q64, radius, cap) > MIN_NEIGHBOURS
        })
        .map(|q| Vec3::from_array(*q).as_dvec3())
        .collect();
    if kept.len() < MIN_POINTS {
        return None;
    }
    let lo = kept.iter().fold(DVec3::INFINITY, |a, q| a.min(*q));
    let hi = kept.iter().fold(DVec3::NEG_INFINITY, |a, q| a.max(*q));
    let grow = ((hi - lo) * GROW).max(DVec3::splat(radius));
    let how = format!(
        "extent of {} of the {in_region} sparse points within {:.3} of it ({planes} planes \
         such as a floor or wall set aside with {on_planes} points, {} points farther than \
         {:.3}, {} isolated points), grown by {:.0} % per side",
        kept.len(),
        REGION * d,
        region.len() - near.len(),
        NEAR * d,
        near.len() - kept.len(),
        GROW * 100.0
    );
    Some((lo - grow, hi + grow, how))
}

/// The plane through three of `points` that most others lie within `tolerance` of (RANSAC):
/// its unit normal and a point on it.
fn best_plane(
    points: &[DVec3],
    tolerance: f64,
    rng: &mut rand_pcg::Pcg64,
) -> Option<(DVec3, DVec3)> {
    let mut best: Option<(usize, DVec3, DVec3)> = None;
    for _ in 0..RANSAC_DRAWS {
        let [a, b, c] = [0; 3].map(|_| points[rng.random_range(0..points.len())]);
        let n = (b - a).cross(c - a);
        if n.length() <= 1e-12 {
            continue;
        }
        let n = n.normalize();
        let count = points
            .iter()
            .filter(|q| (**q - a).dot(n).abs() <= tolerance)
            .count();
        if best.is_none_or(|(k, _, _)| count > k) {
            best = Some((count, n, a));
        }
    }
    best.map(|(_, n, o)| (n, o))
}

/// How far a set of points spreads: the 90th percentile of their distances from their mean.
fn spread(points: &[DVec3]) -> f64 {
    let mean = points.iter().copied().sum::<DVec3>() / points.len() as f64;
    let mut r: Vec<f64> = points.iter().map(|q| (*q - mean).length()).collect();
    r.sort_by(f64::total_cmp);
    r[(0.9 * (r.len() - 1) as f64) as usize]
}

/// The median of `v` (the upper one for an even count); 0 for none.
fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}
