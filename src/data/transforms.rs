//! The `transforms.json` schema that the NeRF-synthetic layout (`transforms_{train,val,test}.json`)
//! and the instant-ngp / nerfstudio layout (one `transforms.json`) share: intrinsics at the top
//! level or per frame (`camera_angle_x`/`_y` or `fl_x`/`fl_y`/`cx`/`cy`, `w`/`h`), the lens
//! (`camera_model` PINHOLE or OPENCV with `k1`, `k2`, `k3`, `p1`, `p2`), camera-to-world
//! matrices in the OpenGL convention, and image paths inside the dataset directory.
//!
//! No distortion coefficient is ignored: a lens model or a coefficient the loader does not apply
//! (OPENCV_FISHEYE, instant-ngp's `is_fisheye`, `k4`…`k6`, `s1`…`s4`, any nonzero coefficient on a
//! PINHOLE camera) is an error naming it.

use super::camera::{focal_from_angle, Camera};
use super::distortion::Distortion;
use super::error::DataError;
use glam::Mat4;
use serde::Deserialize;
use std::path::{Component, Path, PathBuf};

/// Distortion keys of instant-ngp / nerfstudio / COLMAP's FULL_OPENCV and thin-prism models that
/// the loader does not apply: refused when nonzero.
const UNAPPLIED_KEYS: [&str; 7] = ["k4", "k5", "k6", "s1", "s2", "s3", "s4"];

/// Intrinsics and lens that may appear at the top level or per frame (nerfstudio).
#[derive(Deserialize, Default, Clone, Debug)]
pub(super) struct Intrinsics {
    camera_angle_x: Option<f64>,
    camera_angle_y: Option<f64>,
    fl_x: Option<f64>,
    fl_y: Option<f64>,
    cx: Option<f64>,
    cy: Option<f64>,
    pub(super) w: Option<f64>,
    pub(super) h: Option<f64>,
    camera_model: Option<String>,
    k1: Option<f64>,
    k2: Option<f64>,
    k3: Option<f64>,
    p1: Option<f64>,
    p2: Option<f64>,
    is_fisheye: Option<bool>,
    k4: Option<f64>,
    k5: Option<f64>,
    k6: Option<f64>,
    s1: Option<f64>,
    s2: Option<f64>,
    s3: Option<f64>,
    s4: Option<f64>,
}

impl Intrinsics {
    /// Each field from `self`, else from `d` (a frame's over the file's).
    pub(super) fn or(self, d: &Intrinsics) -> Intrinsics {
        Intrinsics {
            camera_angle_x: self.camera_angle_x.or(d.camera_angle_x),
            camera_angle_y: self.camera_angle_y.or(d.camera_angle_y),
            fl_x: self.fl_x.or(d.fl_x),
            fl_y: self.fl_y.or(d.fl_y),
            cx: self.cx.or(d.cx),
            cy: self.cy.or(d.cy),
            w: self.w.or(d.w),
            h: self.h.or(d.h),
            camera_model: self.camera_model.or_else(|| d.camera_model.clone()),
            k1: self.k1.or(d.k1),
            k2: self.k2.or(d.k2),
            k3: self.k3.or(d.k3),
            p1: self.p1.or(d.p1),
            p2: self.p2.or(d.p2),
            is_fisheye: self.is_fisheye.or(d.is_fisheye),
            k4: self.k4.or(d.k4),
            k5: self.k5.or(d.k5),
            k6: self.k6.or(d.k6),
            s1: self.s1.or(d.s1),
            s2: self.s2.or(d.s2),
            s3: self.s3.or(d.s3),
            s4: self.s4.or(d.s4),
        }
    }

    /// The lens: `camera_model` PINHOLE (no coefficient may be nonzero) or OPENCV (also when
    /// absent, as instant-ngp writes it), with k1, k2, k3, p1, p2. `frame` names the frame in
    /// errors.
    pub(super) fn distortion(&self, json: &Path, frame: usize) -> Result<Distortion, DataError> {
        let refuse = |msg: String| DataError::Format {
            path: json.to_path_buf(),
            msg: format!("frame {frame}: {msg}"),
        };
        let model = self.camera_model.as_deref().unwrap_or("OPENCV");
        if self.is_fisheye == Some(true) || model == "OPENCV_FISHEYE" {
            let named = if model == "OPENCV_FISHEYE" {
                "camera_model OPENCV_FISHEYE"
            } else {
                "is_fisheye: true"
            };
            return Err(refuse(format!(
                "{named}: fisheye lenses are not supported; undistort the images to a pinhole \
                 camera first (e.g. colmap image_undistorter, or ns-process-data with \
                 --camera-type perspective)"
            )));
        }
        let unapplied = [
            self.k4, self.k5, self.k6, self.s1, self.s2, self.s3, self.s4,
        ];
        if let Some((key, v)) = UNAPPLIED_KEYS
            .iter()
            .zip(unapplied)
            .find_map(|(k, v)| v.filter(|&v| v != 0.0).map(|v| (k, v)))
        {
            return Err(refuse(format!(
                "distortion coefficient {key} = {v} is not applied by the loader (it applies \
                 OPENCV's k1, k2, k3, p1, p2); undistort the images first"
            )));
        }
        let coeffs = [
            ("k1", self.k1),
            ("k2", self.k2),
            ("k3", self.k3),
            ("p1", self.p1),
            ("p2", self.p2),
        ];
        if let Some((key, v)) = coeffs.iter().find_map(|&(k, v)| v.map(|v| (k, v))) {
            if !v.is_finite() {
                return Err(refuse(format!("distortion coefficient {key} = {v}")));
            }
        }
        let [k1, k2, k3, p1, p2] = coeffs.map(|(_, v)| v.unwrap_or(0.0));
        match model {
            "PINHOLE" => match coeffs.iter().find(|(_, v)| v.is_some_and(|v| v != 0.0)) {
                Some((key, v)) => Err(refuse(format!(
                    "camera_model PINHOLE has no distortion, but {key} = {} is given: set \
                     camera_model OPENCV to apply it, or remove it",
                    v.unwrap_or(0.0)
                ))),
                None => Ok(Distortion::None),
            },
            "OPENCV" => Ok(Distortion::OpenCv { k1, k2, k3, p1, p2 }),
            other => Err(refuse(format!(
                "camera_model {other} is not supported (the loader reads PINHOLE and OPENCV); \
                 undistort the images to a pinhole camera first"
            ))),
        }
    }

    /// The pinhole camera of a frame whose image is `w`×`h` (full resolution) at pose `c2w`;
    /// `frame` names the frame in errors.
    pub(super) fn camera(
        &self,
        json: &Path,
        frame: usize,
        c2w: Mat4,
        w: u32,
        h: u32,
    ) -> Result<Camera, DataError> {
        let fmt = |msg: String| DataError::Format {
            path: json.to_path_buf(),
            msg: format!("frame {frame}: {msg}"),
        };
        // An angle at or past π (or in degrees) gives a zero or negative focal, and f32 rounding
        // can turn an f64 angle just below π into one past it: checked on the f32 focal used.
        for (angle, name, size) in [
            (self.camera_angle_x, "camera_angle_x", w),
            (self.camera_angle_y, "camera_angle_y", h),
        ] {
            if let Some(a) = angle {
                let f = focal_from_angle(size, a as f32);
                if !(a > 0.0 && a < std::f64::consts::PI && f > 0.0 && f.is_finite()) {
                    return Err(fmt(format!(
                        "{name} = {a} rad: expected a field of view in (0, π) radians whose \
                         focal length is positive in single precision (got {f} px)"
                    )));
                }
            }
        }
        let fx = match (self.fl_x, self.camera_angle_x) {
            (Some(f), _) => f,
            (None, Some(a)) => 0.5 * w as f64 / (0.5 * a).tan(),
            (None, None) => return Err(fmt("neither camera_angle_x nor fl_x is given".into())),
        };
        let fy = match (self.fl_y, self.camera_angle_y) {
            (Some(f), _) => f,
            (None, Some(a)) => 0.5 * h as f64 / (0.5 * a).tan(),
            (None, None) => fx,
        };
        let cx = self.cx.unwrap_or(0.5 * w as f64);
        let cy = self.cy.unwrap_or(0.5 * h as f64);
        for (v, name) in [(fx, "focal x"), (fy, "focal y"), (cx, "cx"), (cy, "cy")] {
            if !v.is_finite() || (name.starts_with("focal") && v <= 0.0) || (v as f32).is_infinite()
            {
                return Err(fmt(format!("invalid {name} = {v}")));
            }
        }
        let mut camera = Camera {
            c2w,
            fx: fx as f32,
            fy: fy as f32,
            cx: cx as f32,
            cy: cy as f32,
            width: w,
            height: h,
        };
        if let (None, Some(a)) = (self.fl_x, self.camera_angle_x) {
            // The exact f32 formula the scene generator uses, so re-rendering is bit-exact.
            camera.fx = focal_from_angle(w, a as f32);
            if self.fl_y.is_none() && self.camera_angle_y.is_none() {
                camera.fy = camera.fx;
            }
        }
        Ok(camera)
    }

    /// The declared image size (`w`, `h`), when both are given, as whole positive pixels.
    pub(super) fn size(&self, json: &Path, frame: usize) -> Result<Option<(u32, u32)>, DataError> {
        let (Some(w), Some(h)) = (self.w, self.h) else {
            return Ok(None);
        };
        let ok = |v: f64| v >= 1.0 && v <= (1u32 << 16) as f64 && v.fract() == 0.0;
        if !ok(w) || !ok(h) {
            return Err(DataError::Format {
                path: json.to_path_buf(),
                msg: format!("frame {frame}: image size w = {w}, h = {h} is not in 1..=65536"),
            });
        }
        Ok(Some((w as u32, h as u32)))
    }
}

/// A frame as the file lists it.
#[derive(Deserialize)]
pub(super) struct FrameJson {
    pub(super) file_path: String,
    pub(super) transform_matrix: Vec<Vec<f64>>,
    /// nerfstudio: the frame's mask (white = object), relative to the dataset directory.
    #[serde(default)]
    pub(super) mask_path: Option<String>,
    #[serde(flatten)]
    pub(super) intr: Intrinsics,
}

/// Reads and parses a JSON file into `T`; errors name the file, line and column.
pub(super) fn read_json<T: serde::de::DeserializeOwned>(json: &Path) -> Result<T, DataError> {
    let text = std::fs::read_to_string(json).map_err(|e| DataError::Format {
        path: json.to_path_buf(),
        msg: format!("cannot read: {e}"),
    })?;
    serde_json::from_str(&text).map_err(|e| DataError::Json {
        path: json.to_path_buf(),
        line: e.line(),
        column: e.column(),
        msg: {
            let full = e.to_string();
            let suffix = format!(" at line {} column {}", e.line(), e.column());
            full.strip_suffix(&suffix).unwrap_or(&full).to_string()
        },
    })
}

/// Checks and converts a 4×4 (or 3×4) matrix given as rows (a camera-to-world or a frame
/// change); `Err` says what is wrong with it.
pub(super) fn parse_matrix(rows: &[Vec<f64>]) -> Result<Mat4, String> {
    if !(rows.len() == 4 || rows.len() == 3) || rows.iter().any(|r| r.len() != 4) {
        let shape: Vec<usize> = rows.iter().map(|r| r.len()).collect();
        return Err(format!(
            "must be 4x4 (or 3x4) but has row lengths {shape:?}"
        ));
    }
    let mut m = [[0f32; 4]; 4];
    m[3] = [0.0, 0.0, 0.0, 1.0];
    for (r, row) in rows.iter().enumerate() {
        for (c, &v) in row.iter().enumerate() {
            let f = v as f32;
            if !f.is_finite() {
                return Err(format!("has a non-finite entry {v} at row {r}, column {c}"));
            }
            m[r][c] = f;
        }
    }
    let last = m[3];
    if (last[0].abs() + last[1].abs() + last[2].abs() + (last[3] - 1.0).abs()) > 1e-4 {
        return Err(format!("has last row {last:?}, expected [0, 0, 0, 1]"));
    }
    // glam is column-major: transpose the rows.
    let c2w = Mat4::from_cols_array_2d(&m).transpose();
    let det = glam::Mat3::from_mat4(c2w).determinant();
    if det.abs() < 1e-6 || !det.is_finite() {
        return Err(format!("is singular (rotation determinant {det:e})"));
    }
    Ok(c2w)
}

/// A frame's camera-to-world `transform_matrix` ([`parse_matrix`]).
pub(super) fn parse_transform(
    json: &Path,
    frame: usize,
    rows: &[Vec<f64>],
) -> Result<Mat4, DataError> {
    parse_matrix(rows).map_err(|problem| DataError::BadTransform {
        path: json.to_path_buf(),
        frame,
        problem,
    })
}

/// Resolves a frame's `file_path` inside `root` (lexically: `..` may not climb out, absolute
/// paths must lie under `root`) to a relative path; `Err` when it escapes or names no file.
pub(super) fn relative_path(
    root: &Path,
    json: &Path,
    frame: usize,
    file_path: &str,
) -> Result<PathBuf, DataError> {
    let escape = || DataError::PathEscape {
        path: json.to_path_buf(),
        frame,
        file_path: file_path.into(),
    };
    let p = Path::new(file_path);
    let rel: PathBuf = if p.is_absolute() {
        p.strip_prefix(root).map_err(|_| escape())?.to_path_buf()
    } else {
        p.to_path_buf()
    };
    let mut depth: i64 = 0;
    let mut clean = PathBuf::new();
    for c in rel.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                depth -= 1;
                if depth < 0 {
                    return Err(escape());
                }
                clean.pop();
            }
            Component::Normal(s) => {
                depth += 1;
                clean.push(s);
            }
            Component::RootDir | Component::Prefix(_) => return Err(escape()),
        }
    }
    if depth == 0 {
        return Err(DataError::Format {
            path: json.to_path_buf(),
            msg: format!("frame {frame}: file_path '{file_path}' names no file"),
        });
    }
    Ok(clean)
}

/// Resolves a frame's `file_path` inside `root` ([`relative_path`]), appending `.png` when the
/// path has no such file itself (Blender writes "./train/r_0").
pub(super) fn resolve_image(
    root: &Path,
    json: &Path,
    frame: usize,
    file_path: &str,
) -> Result<PathBuf, DataError> {
    let direct = root.join(relative_path(root, json, frame, file_path)?);
    if direct.is_file() {
        return Ok(direct);
    }
    let mut with_png = direct.clone().into_os_string();
    with_png.push(".png");
    let with_png = PathBuf::from(with_png);
    if with_png.is_file() {
        return Ok(with_png);
    }
    // Present but not a readable file (a folder without permission, a symbolic link loop):
    // the reason, not "not found".
    for p in [&direct, &with_png] {
        if let Some(why) = super::image::unreadable_reason(p) {
            return Err(DataError::UnreadableImage {
                path: p.clone(),
                msg: format!("{why} (frame {frame} of {})", json.display()),
            });
        }
    }
    Err(DataError::MissingImage {
        path: if direct.extension().is_some() {
            direct
        } else {
            with_png
        },
        json: json.to_path_buf(),
        frame,
    })
}
