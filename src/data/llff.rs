//! The LLFF layout (the paper's real-world captures): `poses_bounds.npy`, N × 17 float rows, each
//! the 3 × 5 matrix [down, right, back, centre | H, W, focal] row-major and the near and far
//! depths; the images are the PNG/JPEG files of `images/` sorted by name (`images_4/`,
//! `images_8/`, … with `--downscale` when they exist: LLFF's own downscaled copies, their names
//! need not match). Optional `masks/` as for COLMAP. Without a `split.json` every 8th image by
//! name is held out (LLFF's convention).
//!
//! Cameras: the rotation's columns (down, right, back) become OpenGL's (right, up, back) =
//! (right, −down, back); focal in pixels of the full H × W image, principal point at its centre.
//! The scene box is the foreground box found from the cameras ([`super::foreground`]: the file
//! holds no sparse points, so it is the cube the median camera's view spans where the optical axes
//! converge), or, when they do not converge, the cube from the nearest near depth to the farthest
//! far depth in front of the mean camera.

use super::aabb::Aabb;
use super::camera::Camera;
use super::distortion::Distortion;
use super::error::DataError;
use super::foreground;
use super::idr::list_images;
use super::views::{self, Posed, View};
use glam::{Mat4, Vec3, Vec4};
use std::path::Path;

/// The file this layout is detected by.
pub const FILE: &str = "poses_bounds.npy";

/// The posed views and scene box of the LLFF dataset `root` (`k`: the requested downscale, which
/// picks the image folder); no image is read.
pub fn posed(root: &Path, k: u32) -> Result<Posed, DataError> {
    let path = root.join(FILE);
    let format = |msg: String| DataError::Format {
        path: path.clone(),
        msg,
    };
    let file = std::fs::File::open(&path).map_err(|e| format(format!("cannot read: {e}")))?;
    let (shape, v) = crate::grid::npz::read_npy_f64(std::io::BufReader::new(file))
        .map_err(|e| format(format!("{e:#}")))?;
    if shape.len() != 2 || shape[1] != 17 || shape[0] == 0 {
        return Err(format(format!(
            "shape {shape:?}: expected N × 17 (a 3 × 5 pose-and-intrinsics matrix and near, far \
             per image)"
        )));
    }
    if let Some(x) = v.iter().find(|x| !x.is_finite()) {
        return Err(format(format!("holds a non-finite value {x}")));
    }
    let folders = views::folders(root, "images", "masks", k);
    let files = list_images(&folders.images)?;
    let n = shape[0] as usize;
    if files.len() != n {
        return Err(DataError::CountMismatch {
            path: folders.images.clone(),
            msg: format!("{} images, but {} poses {n}", files.len(), path.display()),
        });
    }
    let mut views = Vec::with_capacity(n);
    let mut depths = Vec::with_capacity(n);
    for (i, file) in files.into_iter().enumerate() {
        let row = &v[17 * i..17 * (i + 1)];
        let m = |r: usize, c: usize| row[5 * r + c] as f32;
        let (h, w, f) = (row[4], row[9], row[14]);
        let whole = |x: f64| x >= 1.0 && x <= (1u32 << 16) as f64 && x.fract() == 0.0;
        if !(whole(h) && whole(w) && f > 0.0) {
            return Err(format(format!(
                "image {i}: H {h}, W {w}, focal {f}: expected whole sizes in 1..=65536 and a \
                 positive focal length"
            )));
        }
        let (near, far) = (row[15], row[16]);
        if !(near > 0.0 && far > near) {
            return Err(format(format!(
                "image {i}: near {near}, far {far}: expected depth bounds 0 < near < far (the \
                 scene's nearest and farthest depths in that view)"
            )));
        }
        let col = |c: usize| Vec3::new(m(0, c), m(1, c), m(2, c));
        let c2w = Mat4::from_cols(
            col(1).extend(0.0),
            (-col(0)).extend(0.0),
            col(2).extend(0.0),
            Vec4::from((col(3), 1.0)),
        );
        let det = glam::Mat3::from_mat4(c2w).determinant();
        if det.abs() < 1e-6 {
            return Err(format(format!(
                "image {i}: the rotation is singular (determinant {det:e})"
            )));
        }
        let (w, h) = (w as u32, h as u32);
        let name = file
            .file_name()
            .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
        views.push(View {
            mask: folders.masks.as_ref().map(|m| m.join(&name)),
            name,
            file,
            camera: Camera {
                c2w,
                fx: f as f32,
                fy: f as f32,
                cx: 0.5 * w as f32,
                cy: 0.5 * h as f32,
                width: w,
                height: h,
            },
            distortion: Distortion::None,
        });
        depths.push((near, far));
    }
    // At least one row, each with 0 < near < far (checked above): both are finite.
    let near = depths.iter().map(|d| d.0).fold(f64::INFINITY, f64::min) as f32;
    let far = depths.iter().map(|d| d.1).fold(0.0, f64::max) as f32;
    let cameras: Vec<Camera> = views.iter().map(|v| v.camera).collect();
    let foreground = foreground::find(&cameras, &[]);
    let scene = match &foreground {
        Some(fg) => fg.bounds.scene_box(),
        None => depth_box(&cameras, near, far).scene_box(),
    };
    Ok(Posed {
        views,
        folders,
        source: path,
        scene,
        foreground,
        nearest: Some(near),
    })
}

/// The cube from depth `near` to depth `far` along the mean camera's axis.
fn depth_box(cameras: &[Camera], near: f32, far: f32) -> Aabb {
    let n = cameras.len() as f32;
    let centre = cameras.iter().map(|c| c.centre()).sum::<Vec3>() / n;
    let axis = cameras
        .iter()
        .map(|c| c.forward())
        .sum::<Vec3>()
        .normalize_or_zero();
    let mid = centre + axis * 0.5 * (near + far);
    let half = Vec3::splat(0.5 * (far - near).max(1e-3));
    Aabb::new(mid - half, mid + half)
}
