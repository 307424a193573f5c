//! Pinhole cameras in the NeRF-synthetic (Blender/OpenGL) convention.
//!
//! Convention (pinned by `tests/pipeline/data_fixture.rs`): `c2w` maps camera to world coordinates; the
//! camera looks down its −Z axis with +Y up and +X right. Pixel (u, v) has its centre at continuous
//! image coordinates (u + 0.5, v + 0.5), with v growing downwards, so the ray through image point
//! (px, py) has camera-frame direction ((px − cx)/fx, −(py − cy)/fy, −1). Converting to the OpenCV
//! convention would be right-multiplying `c2w` by diag(1, −1, −1, 1); we never do.

use glam::{Mat4, Vec3, Vec4};

/// A pinhole camera in Blender world units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Camera-to-world, OpenGL convention.
    pub c2w: Mat4,
    /// Focal length in pixels, x.
    pub fx: f32,
    /// Focal length in pixels, y.
    pub fy: f32,
    /// Principal point in continuous pixel coordinates (pixel centres at +0.5).
    pub cx: f32,
    /// Principal point, y.
    pub cy: f32,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}

/// focal = 0.5·W / tan(0.5·camera_angle_x).
pub fn focal_from_angle(width: u32, angle: f32) -> f32 {
    0.5 * width as f32 / (0.5 * angle).tan()
}

impl Camera {
    /// A camera with `camera_angle_x`, square pixels and the principal point at the image centre.
    pub fn from_angle_x(c2w: Mat4, width: u32, height: u32, camera_angle_x: f32) -> Camera {
        let f = focal_from_angle(width, camera_angle_x);
        Camera {
            c2w,
            fx: f,
            fy: f,
            cx: 0.5 * width as f32,
            cy: 0.5 * height as f32,
            width,
            height,
        }
    }

    /// Camera centre in world coordinates.
    pub fn centre(&self) -> Vec3 {
        self.c2w.w_axis.truncate()
    }

    /// Unit viewing direction (the camera's −Z axis) in world coordinates.
    pub fn forward(&self) -> Vec3 {
        (-self.c2w.z_axis.truncate()).normalize()
    }

    /// Ray through continuous image point (px, py): origin and unit direction, world units.
    pub fn ray_at(&self, px: f32, py: f32) -> (Vec3, Vec3) {
        let d_cam = Vec3::new((px - self.cx) / self.fx, -(py - self.cy) / self.fy, -1.0);
        let d = self.c2w.transform_vector3(d_cam).normalize();
        (self.centre(), d)
    }

    /// Ray through the centre of pixel (u, v).
    pub fn pixel_ray(&self, u: u32, v: u32) -> (Vec3, Vec3) {
        self.ray_at(u as f32 + 0.5, v as f32 + 0.5)
    }

    /// Projects a world point: continuous image coordinates (px, py) and the depth along the
    /// viewing axis; `None` if the point is not in front of the camera.
    pub fn project(&self, p: Vec3) -> Option<(f32, f32, f32)> {
        let q = self.c2w.inverse() * Vec4::new(p.x, p.y, p.z, 1.0);
        let depth = -q.z;
        if depth <= 1e-6 {
            return None;
        }
        let px = self.cx + self.fx * q.x / depth;
        let py = self.cy - self.fy * q.y / depth;
        Some((px, py, depth))
    }

    /// The same camera for images box-downscaled by `k` (floor(W/k) × floor(H/k)).
    pub fn downscaled(&self, k: u32) -> Camera {
        let s = 1.0 / k as f32;
        Camera {
            c2w: self.c2w,
            fx: self.fx * s,
            fy: self.fy * s,
            cx: self.cx * s,
            cy: self.cy * s,
            width: self.width / k,
            height: self.height / k,
        }
    }
}

/// Camera-to-world (OpenGL convention) for a camera at `eye` looking at `target`, with `up` the
/// world's up direction (Blender: +Z). `up` must not be parallel to the viewing direction.
pub fn look_at(eye: Vec3, target: Vec3, up: Vec3) -> Mat4 {
    let z = (eye - target).normalize();
    let x = up.cross(z).normalize();
    let y = z.cross(x);
    Mat4::from_cols(x.extend(0.0), y.extend(0.0), z.extend(0.0), eye.extend(1.0))
}

/// Entry and exit distances of a ray with an axis-aligned box, if it meets it at t ≥ 0.
pub fn ray_box(o: Vec3, d: Vec3, lo: Vec3, hi: Vec3) -> Option<(f32, f32)> {
    let inv = d.recip();
    let t0 = (lo - o) * inv;
    let t1 = (hi - o) * inv;
    let tmin = t0.min(t1).max_element().max(0.0);
    let tmax = t0.max(t1).min_element();
    (tmin <= tmax).then_some((tmin, tmax))
}
