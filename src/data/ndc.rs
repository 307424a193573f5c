//! The NDC space of a forward-facing capture (the paper's and svox2's set-up for LLFF scenes):
//! the frame it is taken in (the mean camera), the projective map's constants, which captures get
//! it (`--space`), and the maps of points and normals between it and dataset units. The grid
//! spans the NDC cube [−1, 1]³: the frame camera's view from the near plane to infinite depth.

use super::camera::Camera;
use crate::abi::buffers::SampleCamera;
use crate::abi::rays::NdcProjection;
use crate::math::ndc::ndc_ray;
use crate::math::percentile::percentile;
use glam::{DMat3, DVec3, Mat3, Vec3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// A layout is forward-facing when every training camera looks within this angle (degrees) of
/// the cameras' mean viewing direction (LLFF captures: about 10–30°; a 360° orbit: 90° and more).
pub const FORWARD_SPREAD_DEG: f64 = 45.0;
/// The near plane lies at this share of the nearest scene depth ([`nearest_depth`]), as svox2's
/// LLFF loader places it (bd_factor 0.75).
pub const NEAR_SHARE: f32 = 0.75;
/// The nearest scene depth is this percentile of the sparse points' depths in view (robust to a
/// few mismatched points in front of the cameras).
pub const NEAR_PERCENTILE: f64 = 0.01;

/// Where the grid lies: a box in the scaled world, or the NDC cube of a forward-facing capture.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Space {
    /// NDC for a forward-facing capture with a near depth, else the box.
    #[default]
    Auto,
    /// A box around the object (the layout's, or `--box`).
    Box,
    /// The NDC cube of the mean camera (forward-facing captures).
    Ndc,
}

/// An NDC space: its frame (a rigid pose in dataset units, looking down its −z axis) and map.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Ndc {
    /// The frame's axes in dataset units (columns x, y, z: orthonormal, right-handed).
    pub axes: [[f32; 3]; 3],
    /// The frame's origin, dataset units.
    pub origin: [f32; 3],
    pub projection: NdcProjection,
}

impl Ndc {
    /// The space of the cameras' mean pose (mean centre; mean viewing direction; up from the
    /// mean of their up axes), the near plane at `near` (dataset units, > 0) and the projection
    /// of the first camera's intrinsics.
    pub fn fit(cameras: &[Camera], near: f32) -> Ndc {
        let n = cameras.len().max(1) as f64;
        let mean = |f: &dyn Fn(&Camera) -> DVec3| cameras.iter().map(f).sum::<DVec3>() / n;
        let centre = mean(&|c| c.centre().as_dvec3());
        let z = -mean(&|c| c.forward().as_dvec3()).normalize();
        let up = mean(&|c| c.c2w.y_axis.truncate().as_dvec3());
        let x = up.cross(z).normalize();
        let y = z.cross(x);
        let c = &cameras[0];
        Ndc {
            axes: [x, y, z].map(|a| a.as_vec3().to_array()),
            origin: centre.as_vec3().to_array(),
            projection: NdcProjection {
                near,
                sx: 2.0 * c.fx / c.width as f32,
                sy: 2.0 * c.fy / c.height as f32,
            },
        }
    }

    fn rotation(&self) -> DMat3 {
        DMat3::from_cols_array_2d(&self.axes.map(|a| a.map(f64::from)))
    }

    /// Dataset units → the frame (f64).
    fn to_frame(self, p: DVec3) -> DVec3 {
        self.rotation().transpose() * (p - DVec3::from_array(self.origin.map(f64::from)))
    }

    /// A camera as the ray sampler takes it, in the frame (the sampler then maps each ray with
    /// [`NdcProjection`]).
    pub fn sample_camera(&self, c: &Camera) -> SampleCamera {
        let m = c.c2w;
        let axis = |a: Vec3| self.frame_direction(a).to_array();
        SampleCamera {
            x_axis: axis(m.x_axis.truncate()),
            y_axis: axis(m.y_axis.truncate()),
            z_axis: axis(m.z_axis.truncate()),
            origin: self.to_frame(c.centre().as_dvec3()).as_vec3().to_array(),
            focal: [c.fx, c.fy],
            centre: [c.cx, c.cy],
        }
    }

    /// The NDC ray (origin, unit direction) of a ray from `o` along unit `d`, dataset units: the
    /// host's copy of the sampler's map (the same camera-frame values, then `ndc_ray`).
    pub fn ray(&self, o: Vec3, d: Vec3) -> [f32; 6] {
        let of = self.to_frame(o.as_dvec3()).as_vec3().to_array();
        ndc_ray(of, self.frame_direction(d).to_array(), self.projection)
    }

    /// A direction in dataset units → the frame (f32, as the sampler's cameras carry it).
    fn frame_direction(&self, d: Vec3) -> Vec3 {
        Mat3::from_cols_array_2d(&self.axes).transpose() * d
    }

    /// A point in dataset units → NDC; `None` behind the frame's camera plane.
    pub fn to_ndc(self, p: [f32; 3]) -> Option<[f32; 3]> {
        let [x, y, z, w] = self.homogeneous(p);
        (w > 0.0).then(|| [x / w, y / w, z / w].map(|v| v as f32))
    }

    /// A point (dataset units) in homogeneous NDC coordinates [x, y, z, w], w its depth along
    /// the frame's view (−q.z): (x, y, z)/w is its NDC point when w > 0; a point on the frame
    /// camera's plane has w = 0 (at infinity), one behind it w < 0 (reached from the scene
    /// through infinity). From a point c of the cube, the line toward it runs along
    /// (x, y, z) − w·c either way.
    pub fn homogeneous(self, p: [f32; 3]) -> [f64; 4] {
        let q = self.to_frame(DVec3::from_array(p.map(f64::from)));
        let (n, sx, sy) = self.constants();
        [sx * q.x, sy * q.y, -(q.z + 2.0 * n), -q.z]
    }

    /// An NDC point (z < 1) → the frame (f64).
    fn frame_point(self, p: [f32; 3]) -> DVec3 {
        let (n, sx, sy) = self.constants();
        let [x, y, z] = p.map(f64::from);
        let qz = 2.0 * n / (z - 1.0);
        DVec3::new(-x * qz / sx, -y * qz / sy, qz)
    }

    /// An NDC point (z < 1) → dataset units.
    pub fn to_world(self, p: [f32; 3]) -> [f32; 3] {
        let q = self.frame_point(p);
        (self.rotation() * q + DVec3::from_array(self.origin.map(f64::from)))
            .as_vec3()
            .to_array()
    }

    /// A gradient with respect to NDC at NDC point `p` → the gradient with respect to dataset
    /// units (the chain rule through the map's Jacobian; direction and length).
    pub fn gradient_to_world(&self, p: [f32; 3], g: [f64; 3]) -> [f64; 3] {
        let (n, sx, sy) = self.constants();
        let q = self.frame_point(p);
        let (qx, qy, qz) = (q.x, q.y, q.z);
        let gq = DVec3::new(
            -sx / qz * g[0],
            -sy / qz * g[1],
            (sx * qx * g[0] + sy * qy * g[1] - 2.0 * n * g[2]) / (qz * qz),
        );
        (self.rotation() * gq).to_array()
    }

    /// A direction `v` (dataset units) at NDC point `p` → the NDC direction it moves along
    /// (the map's Jacobian times `v`).
    pub fn direction_to_ndc(&self, p: [f32; 3], v: [f32; 3]) -> [f32; 3] {
        let (n, sx, sy) = self.constants();
        let q = self.frame_point(p);
        let (qx, qy, qz) = (q.x, q.y, q.z);
        let vq = self.rotation().transpose() * DVec3::from_array(v.map(f64::from));
        [
            -sx * (vq.x / qz - qx * vq.z / (qz * qz)),
            -sy * (vq.y / qz - qy * vq.z / (qz * qz)),
            -2.0 * n * vq.z / (qz * qz),
        ]
        .map(|c| c as f32)
    }

    /// The dataset-unit bounds of the NDC cube's part from the near plane to twice its depth
    /// (NDC z from −1 to 0): where a box-shaped check of the scene can look.
    pub fn near_bounds(&self) -> (Vec3, Vec3) {
        let corners = (0..8).map(|i| {
            let c = [i & 1, (i >> 1) & 1, (i >> 2) & 1].map(|b| b as f32);
            Vec3::from_array(self.to_world([2.0 * c[0] - 1.0, 2.0 * c[1] - 1.0, c[2] - 1.0]))
        });
        corners.fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p), hi.max(p))
        })
    }

    fn constants(&self) -> (f64, f64, f64) {
        let p = self.projection;
        (p.near as f64, p.sx as f64, p.sy as f64)
    }
}

/// The largest angle (degrees) between a camera's viewing direction and the cameras' mean one.
pub fn view_spread_deg(cameras: &[Camera]) -> f64 {
    let mean = cameras
        .iter()
        .map(|c| c.forward().as_dvec3())
        .sum::<DVec3>()
        .normalize_or_zero();
    cameras
        .iter()
        .map(|c| {
            c.forward()
                .as_dvec3()
                .dot(mean)
                .clamp(-1.0, 1.0)
                .acos()
                .to_degrees()
        })
        .fold(0.0, f64::max)
}

/// The nearest depth of the scene in front of the cameras: over every camera, the
/// [`NEAR_PERCENTILE`] of the depths of the sparse points inside its image, the smallest.
pub fn nearest_depth(cameras: &[Camera], points: &[[f64; 3]]) -> Option<f32> {
    cameras
        .par_iter()
        .filter_map(|c| {
            let w2c = c.c2w.as_dmat4().inverse();
            let mut d: Vec<f32> = points
                .iter()
                .filter_map(|p| {
                    let q = w2c.transform_point3(DVec3::from_array(*p));
                    let depth = -q.z;
                    let x = c.cx as f64 + c.fx as f64 * q.x / depth;
                    let y = c.cy as f64 - c.fy as f64 * q.y / depth;
                    let inside =
                        (0.0..c.width as f64).contains(&x) && (0.0..c.height as f64).contains(&y);
                    (depth > 0.0 && inside).then_some(depth as f32)
                })
                .collect();
            d.sort_by(f32::total_cmp);
            (!d.is_empty()).then(|| percentile(&d, NEAR_PERCENTILE))
        })
        .reduce_with(f32::min)
}

/// The space `want` resolves to for these training cameras and nearest scene depth, and why
/// (for `inspect` and the training log). `Space::Ndc` without a nearest depth is an error.
pub fn choose(
    want: Space,
    cameras: &[Camera],
    nearest: Option<f32>,
) -> Result<(Option<Ndc>, String), String> {
    let spread = view_spread_deg(cameras);
    let facing = format!(
        "every camera looks within {spread:.1}° of their mean direction (forward-facing at most \
         {FORWARD_SPREAD_DEG}°)"
    );
    let ndc = |why: &str| match nearest {
        Some(d) if d > 0.0 && d.is_finite() => {
            let near = NEAR_SHARE * d;
            Ok((
                Some(Ndc::fit(cameras, near)),
                format!(
                    "NDC ({why}; nearest scene depth {d:.3}, near plane at {near:.3}, the mean \
                     camera's frame)"
                ),
            ))
        }
        _ => Err(format!(
            "NDC needs the scene's nearest depth (sparse points in view, or LLFF's near \
             bounds), which this dataset lacks ({why})"
        )),
    };
    match want {
        Space::Box => Ok((None, "box (--space box)".into())),
        Space::Ndc if spread >= 90.0 => Err(format!(
            "--space ndc needs a forward-facing capture, but a camera looks {spread:.1}° away \
             from the cameras' mean direction"
        )),
        Space::Ndc => ndc("--space ndc"),
        Space::Auto if spread <= FORWARD_SPREAD_DEG && nearest.is_some() => ndc(&facing),
        Space::Auto if spread <= FORWARD_SPREAD_DEG => Ok((
            None,
            format!("box: {facing}, but no nearest scene depth is known for NDC"),
        )),
        Space::Auto => Ok((
            None,
            format!(
                "box: not forward-facing (a camera looks {spread:.1}° from the cameras' mean \
                 direction; NDC at most {FORWARD_SPREAD_DEG}°)"
            ),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::camera::look_at;

    /// A 3 × 3 grid of cameras in the plane y = −3 aimed at the origin.
    fn cameras() -> Vec<Camera> {
        (0..9)
            .map(|i| {
                let eye = Vec3::new((i % 3) as f32 - 1.0, -3.0, (i / 3) as f32 * 0.5);
                Camera::from_angle_x(look_at(eye, Vec3::ZERO, Vec3::Z), 64, 48, 0.8)
            })
            .collect()
    }

    /// The homogeneous point is the NDC point in front, and the line toward a camera behind the
    /// frame's plane runs away from the scene's side of infinity.
    #[test]
    fn homogeneous_points_agree_with_the_map() {
        let ndc = Ndc::fit(&cameras(), 1.5);
        let p = [0.3f32, -0.4, 0.2];
        let h = ndc.homogeneous(p);
        let q = ndc.to_ndc(p).unwrap();
        for i in 0..3 {
            assert!((h[i] / h[3] - q[i] as f64).abs() < 1e-5);
        }
        // A camera 1 unit behind the frame's plane (w < 0): from the cube's centre the line
        // toward it heads to the near face (−z in NDC), where the world segment leaves the cube.
        let z = Vec3::from_array(ndc.axes[2]);
        let behind = (Vec3::from_array(ndc.origin) + z).to_array();
        let h = ndc.homogeneous(behind);
        assert!(h[3] < 0.0);
        // From the centre (c = 0) the line runs along (x, y, z).
        assert!(h[2] < 0.0, "{h:?}");
    }

    #[test]
    fn points_map_to_ndc_and_back() {
        let ndc = Ndc::fit(&cameras(), 1.5);
        for p in [[0.0, 0.0, 0.0], [0.3, -0.4, 0.2], [-0.5, 2.0, 0.7]] {
            let q = ndc.to_ndc(p).unwrap();
            let back = ndc.to_world(q);
            for i in 0..3 {
                assert!((back[i] - p[i]).abs() < 1e-4, "{p:?} → {q:?} → {back:?}");
            }
        }
        // The origin, ahead of the cameras, lies inside the cube; a point behind them does not map.
        let q = ndc.to_ndc([0.0, 0.0, 0.0]).unwrap();
        assert!(q.iter().all(|v| v.abs() < 1.0), "{q:?}");
        assert!(ndc.to_ndc([0.0, -10.0, 0.0]).is_none());
    }

    /// The host's ray map agrees with the sampler's camera in the frame, and every point of a
    /// camera ray maps onto its NDC ray.
    #[test]
    fn camera_rays_map_onto_their_ndc_rays() {
        let cams = cameras();
        let ndc = Ndc::fit(&cams, 1.5);
        let c = &cams[5];
        let (o, d) = c.pixel_ray(10, 30);
        let r = ndc.ray(o, d);
        for u in [2.0f32, 3.5, 8.0] {
            let m = ndc.to_ndc((o + u * d).to_array()).unwrap();
            let s = (m[2] - r[2]) / r[5];
            for i in 0..3 {
                assert!((r[i] + s * r[3 + i] - m[i]).abs() < 1e-4, "u {u} axis {i}");
            }
        }
    }

    /// The gradient map is the chain rule: a plane's NDC gradient maps to its world normal.
    #[test]
    fn gradients_map_through_the_jacobian() {
        let ndc = Ndc::fit(&cameras(), 1.5);
        let p = [0.2f32, 0.1, -0.3];
        let q = ndc.to_ndc(p).unwrap();
        // f(world) = world x; its NDC gradient by central differences of f ∘ to_world.
        let h = 1e-3f32;
        let g: [f64; 3] = std::array::from_fn(|i| {
            let (mut a, mut b) = (q, q);
            a[i] += h;
            b[i] -= h;
            (ndc.to_world(a)[0] as f64 - ndc.to_world(b)[0] as f64) / (2.0 * h as f64)
        });
        let w = ndc.gradient_to_world(q, g);
        assert!(
            (w[0] - 1.0).abs() < 1e-2 && w[1].abs() < 1e-2 && w[2].abs() < 1e-2,
            "{w:?}"
        );
    }

    /// The direction map is the Jacobian: a small step along it matches the point map.
    #[test]
    fn directions_map_through_the_jacobian() {
        let ndc = Ndc::fit(&cameras(), 1.5);
        let p = [0.2f32, 0.1, -0.3];
        let v = [0.3f32, -0.5, 0.8];
        let q = ndc.to_ndc(p).unwrap();
        let h = 1e-3f32;
        let (a, b) = (
            ndc.to_ndc(std::array::from_fn(|i| p[i] + h * v[i]))
                .unwrap(),
            ndc.to_ndc(std::array::from_fn(|i| p[i] - h * v[i]))
                .unwrap(),
        );
        let j = ndc.direction_to_ndc(q, v);
        for i in 0..3 {
            let fd = (a[i] - b[i]) / (2.0 * h);
            assert!(
                (fd - j[i]).abs() < 1e-2 * j[i].abs().max(0.1),
                "axis {i}: {fd} vs {}",
                j[i]
            );
        }
    }

    #[test]
    fn auto_chooses_ndc_only_for_forward_facing_cameras() {
        let ff = cameras();
        let (ndc, why) = choose(Space::Auto, &ff, Some(2.0)).unwrap();
        assert!(ndc.is_some() && why.starts_with("NDC"), "{why}");
        assert!(choose(Space::Auto, &ff, None).unwrap().0.is_none());
        assert!(choose(Space::Ndc, &ff, None).is_err());
        // Eight cameras on a circle of radius 4 at height z, aimed at the origin.
        let circle = |z: f32| -> Vec<Camera> {
            (0..8)
                .map(|i| {
                    let a = i as f32 * 0.785;
                    let eye = Vec3::new(4.0 * a.cos(), 4.0 * a.sin(), z);
                    Camera::from_angle_x(look_at(eye, Vec3::ZERO, Vec3::Z), 64, 48, 0.8)
                })
                .collect()
        };
        let (ndc, why) = choose(Space::Auto, &circle(1.0), Some(2.0)).unwrap();
        assert!(ndc.is_none() && why.contains("not forward-facing"), "{why}");
        // Asked for, NDC is refused only where a camera looks away from the rest (its rays
        // would run behind the NDC frame): cameras around a level circle.
        assert!(choose(Space::Ndc, &circle(0.0), Some(2.0)).is_err());
    }
}
