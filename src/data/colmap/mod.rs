//! The COLMAP layout: `images/` (optionally `images_2/4/8`), optional `masks/` (alpha from the
//! mask's first channel; `masks/NAME`, `masks/NAME.png` or `masks/STEM.png`) and a sparse model
//! in `sparse/0` or `sparse`, text ([`text`]) or binary ([`binary`]).
//!
//! Cameras: PINHOLE and SIMPLE_PINHOLE as they are; SIMPLE_RADIAL, RADIAL and OPENCV undistorted
//! on load onto the pinhole with the same intrinsics; other models are refused by name. Poses:
//! COLMAP stores world-to-camera (R, t) in the OpenCV convention (+Y down, +Z forward); we keep
//! camera-to-world in the OpenGL one, c2w = [Rᵀ | −Rᵀt]·diag(1, −1, −1, 1). COLMAP's pixel
//! centres are at +0.5, as ours. The scene box: without masks, the foreground box found from the
//! cameras and sparse points ([`super::foreground`]); with masks, or when the optical axes do not
//! converge, the sparse points in view (see [`scene_box`]).

pub mod binary;
pub mod text;

use super::camera::Camera;
use super::distortion::Distortion;
use super::error::DataError;
use super::foreground::POINT_PERCENTILES;
use super::scene_box::SceneBox;
use super::views::{self, Posed, View};
use crate::math::percentile::percentile_bounds;
use glam::{DMat3, DVec3, Mat4, Vec3};
use std::collections::HashMap;
use std::path::{Component, Path, PathBuf};

/// COLMAP's camera models by numeric id (the binary format's), with their parameter counts.
pub const MODELS: [(&str, usize); 11] = [
    ("SIMPLE_PINHOLE", 3),
    ("PINHOLE", 4),
    ("SIMPLE_RADIAL", 4),
    ("RADIAL", 5),
    ("OPENCV", 8),
    ("OPENCV_FISHEYE", 8),
    ("FULL_OPENCV", 12),
    ("FOV", 5),
    ("SIMPLE_RADIAL_FISHEYE", 4),
    ("RADIAL_FISHEYE", 5),
    ("THIN_PRISM_FISHEYE", 12),
];

/// The models the loader reads, for messages.
const SUPPORTED: &str = "PINHOLE, SIMPLE_PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV";

/// The scene box's half-size over the points' half-extent.
pub const BOX_MARGIN: f64 = 1.1;

/// One camera as the model stores it.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraEntry {
    /// Camera id.
    pub id: i64,
    /// Model name (e.g. "PINHOLE").
    pub model: String,
    /// Image width.
    pub width: u64,
    /// Image height.
    pub height: u64,
    /// Model parameters.
    pub params: Vec<f64>,
}

/// One registered image as the model stores it.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageEntry {
    /// Image id.
    pub id: i64,
    /// World-to-camera rotation as a quaternion (w, x, y, z).
    pub q: [f64; 4],
    /// World-to-camera translation.
    pub t: [f64; 3],
    /// Its camera's id.
    pub camera_id: i64,
    /// File name relative to the image folder.
    pub name: String,
}

/// Every sparse point of `path` has a finite position (the points bound the object, and a NaN
/// among them is a damaged model, not a point to pass over).
fn check_points(path: &Path, points: &[[f64; 3]]) -> Result<(), DataError> {
    match points
        .iter()
        .enumerate()
        .find(|(_, p)| !p.iter().all(|v| v.is_finite()))
    {
        None => Ok(()),
        Some((i, p)) => Err(DataError::Format {
            path: path.to_path_buf(),
            msg: format!(
                "point {} (in file order) has a non-finite position {p:?}: the model is damaged",
                i + 1
            ),
        }),
    }
}

/// The posed views and scene box of the COLMAP dataset `root` with its model in `sparse` (`k`:
/// the requested downscale, which picks the image folder); no image is read.
pub fn posed(root: &Path, sparse: &Path, k: u32) -> Result<Posed, DataError> {
    let binary = sparse.join("cameras.bin").is_file();
    let file = |stem: &str| sparse.join(format!("{stem}.{}", if binary { "bin" } else { "txt" }));
    let (cam_file, img_file, pts_file) = (file("cameras"), file("images"), file("points3D"));
    for f in [&img_file, &pts_file] {
        if !f.is_file() {
            return Err(DataError::Format {
                path: f.clone(),
                msg: format!(
                    "not found (the model in {} is incomplete)",
                    sparse.display()
                ),
            });
        }
    }
    let (cams, images, points) = if binary {
        (
            binary::cameras(&cam_file)?,
            binary::images(&img_file)?,
            binary::points(&pts_file)?,
        )
    } else {
        (
            text::cameras(&cam_file)?,
            text::images(&img_file)?,
            text::points(&pts_file)?,
        )
    };
    check_points(&pts_file, &points)?;
    let mut by_id = HashMap::new();
    for c in &cams {
        let intr = intrinsics(&cam_file, c)?;
        if by_id.insert(c.id, (intr, c)).is_some() {
            return Err(DataError::CountMismatch {
                path: cam_file.clone(),
                msg: format!("camera id {} appears twice", c.id),
            });
        }
    }
    if images.is_empty() {
        return Err(DataError::CountMismatch {
            path: img_file,
            msg: "no registered images".into(),
        });
    }
    let folders = views::folders(root, "images", "masks", k);
    let mut posed = Vec::with_capacity(images.len());
    for im in &images {
        let Some(&((fx, fy, cx, cy, distortion), c)) = by_id.get(&im.camera_id) else {
            return Err(DataError::CountMismatch {
                path: img_file.clone(),
                msg: format!(
                    "image '{}' uses camera {}, which {} does not define",
                    im.name,
                    im.camera_id,
                    cam_file.display()
                ),
            });
        };
        let name_ok = Path::new(&im.name)
            .components()
            .all(|c| matches!(c, Component::Normal(_)));
        if !name_ok || im.name.is_empty() {
            return Err(DataError::Format {
                path: img_file.clone(),
                msg: format!(
                    "image name '{}' is not a relative path inside images/",
                    im.name
                ),
            });
        }
        posed.push(View {
            name: im.name.clone(),
            file: folders.images.join(&im.name),
            mask: folders.masks.as_deref().map(|m| mask_file(m, &im.name)),
            camera: Camera {
                c2w: c2w_from_colmap(&img_file, im)?,
                fx,
                fy,
                cx,
                cy,
                width: c.width as u32,
                height: c.height as u32,
            },
            distortion,
        });
    }
    // A capture without masks frames its object in a room: the box is the foreground found
    // from the cameras; with masks (or when the axes do not converge), the points in view.
    let cameras: Vec<Camera> = posed.iter().map(|v| v.camera).collect();
    let foreground = folders
        .masks
        .is_none()
        .then(|| super::foreground::find(&cameras, &points))
        .flatten();
    let scene = match &foreground {
        Some(fg) => fg.bounds.scene_box(),
        None => scene_box(&points, cameras.iter()).ok_or_else(|| DataError::Format {
            path: pts_file.clone(),
            msg: format!(
                "none of its {} points is in view of a registered camera: cannot place the \
                 scene box",
                points.len()
            ),
        })?,
    };
    Ok(Posed {
        views: posed,
        folders,
        source: img_file,
        scene,
        foreground,
        nearest: super::ndc::nearest_depth(&cameras, &points),
    })
}

type Intrinsics = (f32, f32, f32, f32, Distortion);

/// Pinhole intrinsics and distortion of a camera entry, or an error naming the model.
fn intrinsics(path: &Path, c: &CameraEntry) -> Result<Intrinsics, DataError> {
    let refuse = |reason: String| DataError::CameraModel {
        path: path.to_path_buf(),
        camera_id: c.id,
        model: c.model.clone(),
        reason,
    };
    let Some(&(_, n)) = MODELS.iter().find(|m| m.0 == c.model) else {
        return Err(refuse(format!(
            "unknown to COLMAP; the loader reads {SUPPORTED}"
        )));
    };
    let unsupported = || {
        refuse(format!(
            "undistort the images first (colmap image_undistorter) or use {SUPPORTED}"
        ))
    };
    const READ: [&str; 5] = [
        "SIMPLE_PINHOLE",
        "PINHOLE",
        "SIMPLE_RADIAL",
        "RADIAL",
        "OPENCV",
    ];
    if !READ.contains(&c.model.as_str()) {
        return Err(unsupported());
    }
    let bad = |msg: String| DataError::Format {
        path: path.to_path_buf(),
        msg: format!("camera {}: {msg}", c.id),
    };
    if c.params.len() != n {
        return Err(bad(format!(
            "model {} takes {n} parameters after the width and height, this camera has {} \
             (a line reads CAMERA_ID MODEL WIDTH HEIGHT PARAMS[])",
            c.model,
            c.params.len()
        )));
    }
    let p = &c.params;
    let (f, d) = match c.model.as_str() {
        "SIMPLE_PINHOLE" => ([p[0], p[0], p[1], p[2]], Distortion::None),
        "PINHOLE" => ([p[0], p[1], p[2], p[3]], Distortion::None),
        "SIMPLE_RADIAL" => (
            [p[0], p[0], p[1], p[2]],
            Distortion::Radial { k1: p[3], k2: 0.0 },
        ),
        "RADIAL" => (
            [p[0], p[0], p[1], p[2]],
            Distortion::Radial { k1: p[3], k2: p[4] },
        ),
        "OPENCV" => (
            [p[0], p[1], p[2], p[3]],
            Distortion::OpenCv {
                k1: p[4],
                k2: p[5],
                k3: 0.0,
                p1: p[6],
                p2: p[7],
            },
        ),
        _ => return Err(unsupported()),
    };
    if let Some(x) = p.iter().find(|x| !x.is_finite()) {
        return Err(bad(format!("parameter {x} is not finite")));
    }
    if !(f[0] > 0.0 && f[1] > 0.0) {
        return Err(bad(format!(
            "focal length {} / {} is not positive",
            f[0], f[1]
        )));
    }
    let dims_ok = |v: u64| (1..=1 << 16).contains(&v);
    if !dims_ok(c.width) || !dims_ok(c.height) {
        return Err(bad(format!(
            "image size {}x{} is not in 1..=65536",
            c.width, c.height
        )));
    }
    // The radial factor at the image's farthest corner: a lens model COLMAP fits keeps it
    // well inside (0.1, 10); past that, undistorting folds or blows up the image.
    let (k1, k2) = match d {
        Distortion::None => (0.0, 0.0),
        Distortion::Radial { k1, k2 } | Distortion::OpenCv { k1, k2, .. } => (k1, k2),
    };
    let dx = f[2].max(c.width as f64 - f[2]) / f[0];
    let dy = f[3].max(c.height as f64 - f[3]) / f[1];
    let r2 = dx * dx + dy * dy;
    let factor = 1.0 + k1 * r2 + k2 * r2 * r2;
    if !(0.1..10.0).contains(&factor) {
        return Err(bad(format!(
            "distortion k1 {k1}, k2 {k2} scales the image corner's radius by {factor:.3e}: not \
             a lens (check the intrinsics, or undistort with colmap image_undistorter)"
        )));
    }
    Ok((f[0] as f32, f[1] as f32, f[2] as f32, f[3] as f32, d))
}

/// Camera-to-world (OpenGL convention) of a COLMAP world-to-camera pose.
fn c2w_from_colmap(path: &Path, im: &ImageEntry) -> Result<Mat4, DataError> {
    let bad = |problem: String| DataError::BadPose {
        path: path.to_path_buf(),
        image: im.name.clone(),
        problem,
    };
    if im.q.iter().chain(&im.t).any(|v| !v.is_finite()) {
        return Err(bad(format!(
            "non-finite pose: quaternion {:?}, translation {:?}",
            im.q, im.t
        )));
    }
    let [w, x, y, z] = im.q;
    let norm = (w * w + x * x + y * y + z * z).sqrt();
    if norm < 1e-6 {
        return Err(bad(format!("quaternion {:?} has no direction", im.q)));
    }
    let r = DMat3::from_quat(glam::DQuat::from_xyzw(
        x / norm,
        y / norm,
        z / norm,
        w / norm,
    ));
    let rt = r.transpose();
    let centre = -(rt * DVec3::from_array(im.t));
    // Columns of the camera-to-world rotation, with the Y and Z axes flipped (OpenCV → OpenGL).
    let cols = [rt.x_axis, -rt.y_axis, -rt.z_axis];
    let f = |v: DVec3| v.as_vec3().extend(0.0);
    Ok(Mat4::from_cols(
        f(cols[0]),
        f(cols[1]),
        f(cols[2]),
        centre.as_vec3().extend(1.0),
    ))
}

/// The mask of image `name`: `masks/NAME`, `masks/NAME.png` or `masks/STEM.png`, the first that
/// exists (the first when none does, for the error).
fn mask_file(masks: &Path, name: &str) -> PathBuf {
    let exact = masks.join(name);
    let candidates = [
        exact.clone(),
        masks.join(format!("{name}.png")),
        exact.with_extension("png"),
    ];
    candidates
        .iter()
        .find(|p| p.is_file())
        .unwrap_or(&candidates[0])
        .clone()
}

/// The scene box from the sparse points: those in front of some camera and inside its image;
/// per axis their [`POINT_PERCENTILES`] (nearest rank, robust to stray points); the cube around
/// that box's centre with half-size [`BOX_MARGIN`] × its largest half-extent. The scaled world
/// puts the cube at [−1, 1]³ shifted by the centre: scale = 1/half-size. `None` when no point is
/// in view.
pub fn scene_box<'a>(
    points: &[[f64; 3]],
    cameras: impl Iterator<Item = &'a Camera> + Clone,
) -> Option<SceneBox> {
    let w2c: Vec<(Mat4, &Camera)> = cameras.map(|c| (c.c2w.inverse(), c)).collect();
    let in_view = |p: &[f64; 3]| {
        let v = Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32);
        w2c.iter().any(|(m, c)| {
            let q = m.transform_point3(v);
            let depth = -q.z;
            let (px, py) = (c.cx + c.fx * q.x / depth, c.cy - c.fy * q.y / depth);
            depth > 0.0
                && (0.0..=c.width as f32).contains(&px)
                && (0.0..=c.height as f32).contains(&py)
        })
    };
    let kept: Vec<&[f64; 3]> = points.iter().filter(|p| in_view(p)).collect();
    if kept.is_empty() {
        return None;
    }
    let (lo, hi) = percentile_bounds(&kept, POINT_PERCENTILES);
    let mid = DVec3::from_array(lo).lerp(DVec3::from_array(hi), 0.5);
    let half = (0..3).map(|a| 0.5 * (hi[a] - lo[a])).fold(0.0, f64::max) * BOX_MARGIN;
    // A single point (or a flat set) still gets a box: a tenth of the camera distance.
    let half = if half > 0.0 {
        half
    } else {
        let d = w2c
            .iter()
            .map(|(_, c)| (c.centre().as_dvec3() - mid).length());
        0.1 * d.fold(0.0, f64::max).max(1e-3)
    };
    let scale = 1.0 / half;
    Some(SceneBox {
        scale: scale as f32,
        centre: (mid * scale).as_vec3(),
        radius: 1.0,
        ndc: None,
    })
}
