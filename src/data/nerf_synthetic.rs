//! The NeRF-synthetic ("Blender") layout: `transforms_{train,val,test}.json` (val falls back to
//! test), `camera_angle_x` or nerfstudio-style `fl_x`/`fl_y`/`cx`/`cy`/`w`/`h` (top level or per
//! frame), RGBA/RGB PNG and JPEG images loaded in parallel, composited on the background, optionally
//! box-downscaled, and held as 8-bit RGBA.

use super::camera::Camera;
use super::dataset::{Frame, Split};
use super::error::DataError;
use super::image::{composite_and_downscale, decode_file, RgbaImage};
use glam::Mat4;
use rayon::prelude::*;
use serde::Deserialize;
use std::path::{Component, Path, PathBuf};

/// The train, val (if `transforms_val.json` exists) and test splits of `root`, images
/// box-downscaled by `k`.
pub(super) fn load_splits(
    root: &Path,
    k: u32,
    bg: [f32; 3],
) -> Result<(Split, Option<Split>, Split), DataError> {
    let train = load_split(root, "train", k, bg)?.ok_or_else(|| missing(root, "train"))?;
    let test = load_split(root, "test", k, bg)?.ok_or_else(|| missing(root, "test"))?;
    let val = load_split(root, "val", k, bg)?;
    Ok((train, val, test))
}

fn missing(root: &Path, split: &str) -> DataError {
    DataError::MissingSplit {
        split: split.into(),
        path: root.join(format!("transforms_{split}.json")),
    }
}

/// Intrinsics that may appear at the top level or per frame (nerfstudio).
#[derive(Deserialize, Default, Clone, Copy)]
struct Intrinsics {
    camera_angle_x: Option<f64>,
    camera_angle_y: Option<f64>,
    fl_x: Option<f64>,
    fl_y: Option<f64>,
    cx: Option<f64>,
    cy: Option<f64>,
    w: Option<f64>,
    h: Option<f64>,
}

impl Intrinsics {
    fn or(self, d: Intrinsics) -> Intrinsics {
        Intrinsics {
            camera_angle_x: self.camera_angle_x.or(d.camera_angle_x),
            camera_angle_y: self.camera_angle_y.or(d.camera_angle_y),
            fl_x: self.fl_x.or(d.fl_x),
            fl_y: self.fl_y.or(d.fl_y),
            cx: self.cx.or(d.cx),
            cy: self.cy.or(d.cy),
            w: self.w.or(d.w),
            h: self.h.or(d.h),
        }
    }
}

#[derive(Deserialize)]
struct TransformsJson {
    #[serde(flatten)]
    intr: Intrinsics,
    frames: Vec<FrameJson>,
}

#[derive(Deserialize)]
struct FrameJson {
    file_path: String,
    transform_matrix: Vec<Vec<f64>>,
    #[serde(flatten)]
    intr: Intrinsics,
}

/// The training split's camera-to-world poses, in file order, without reading any image.
pub(super) fn train_poses(root: &Path) -> Result<Vec<Mat4>, DataError> {
    let (_, jobs) = parse_split(root, "train")?.ok_or_else(|| missing(root, "train"))?;
    Ok(jobs.into_iter().map(|(_, c2w, _)| c2w).collect())
}

/// One frame before decoding: its image file, camera-to-world pose and intrinsics.
type FrameJob = (PathBuf, Mat4, Intrinsics);

/// Parses and checks `transforms_<name>.json` (poses, image paths, intrinsics) without reading
/// any image; `Ok(None)` if the file does not exist.
fn parse_split(root: &Path, name: &str) -> Result<Option<(PathBuf, Vec<FrameJob>)>, DataError> {
    let json = root.join(format!("transforms_{name}.json"));
    if !json.exists() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&json).map_err(|e| DataError::Format {
        path: json.clone(),
        msg: format!("cannot read: {e}"),
    })?;
    let parsed: TransformsJson = serde_json::from_str(&text).map_err(|e| DataError::Json {
        path: json.clone(),
        line: e.line(),
        column: e.column(),
        msg: {
            let full = e.to_string();
            let suffix = format!(" at line {} column {}", e.line(), e.column());
            full.strip_suffix(&suffix).unwrap_or(&full).to_string()
        },
    })?;
    if parsed.frames.is_empty() {
        return Err(DataError::EmptySplit {
            path: json,
            split: name.into(),
        });
    }
    let mut jobs = Vec::with_capacity(parsed.frames.len());
    for (i, fr) in parsed.frames.iter().enumerate() {
        let c2w = parse_transform(&json, i, &fr.transform_matrix)?;
        let file = resolve_image(root, &json, i, &fr.file_path)?;
        jobs.push((file, c2w, fr.intr.or(parsed.intr)));
    }
    Ok(Some((json, jobs)))
}

/// Loads `transforms_<name>.json` and its images; `Ok(None)` if the file does not exist.
fn load_split(root: &Path, name: &str, k: u32, bg: [f32; 3]) -> Result<Option<Split>, DataError> {
    // Everything cheap is validated before any image is decoded.
    let Some((json, jobs)) = parse_split(root, name)? else {
        return Ok(None);
    };
    // Decode in parallel; report the first failing frame in file order (deterministic).
    let frames: Vec<Result<Frame, DataError>> = jobs
        .into_par_iter()
        .enumerate()
        .map(|(i, (file, c2w, intr))| load_frame(&json, i, file, c2w, intr, k, bg))
        .collect();
    let frames: Vec<Frame> = frames.into_iter().collect::<Result<_, _>>()?;
    let (w, h) = (frames[0].image.width, frames[0].image.height);
    for f in &frames[1..] {
        if (f.image.width, f.image.height) != (w, h) {
            return Err(DataError::MixedSizes {
                path: f.file.clone(),
                got_w: f.image.width * k,
                got_h: f.image.height * k,
                reference: frames[0].file.display().to_string(),
                want_w: w * k,
                want_h: h * k,
            });
        }
    }
    Ok(Some(Split {
        name: name.into(),
        source: json,
        frames,
    }))
}

fn load_frame(
    json: &Path,
    i: usize,
    file: PathBuf,
    c2w: Mat4,
    intr: Intrinsics,
    k: u32,
    bg: [f32; 3],
) -> Result<Frame, DataError> {
    let (w, h, raw, had_alpha) = decode_file(&file)?;
    for (declared, got, what) in [(intr.w, w, "w"), (intr.h, h, "h")] {
        if let Some(d) = declared {
            if d != got as f64 {
                return Err(DataError::MixedSizes {
                    reference: format!("{} ('{what}' = {d})", json.display()),
                    path: file,
                    got_w: w,
                    got_h: h,
                    want_w: intr.w.map_or(w, |v| v as u32),
                    want_h: intr.h.map_or(h, |v| v as u32),
                });
            }
        }
    }
    let fmt = |msg: String| DataError::Format {
        path: json.to_path_buf(),
        msg: format!("frame {i}: {msg}"),
    };
    // An angle at or past π (or in degrees) gives a zero or negative focal, and f32 rounding
    // can turn an f64 angle just below π into one past it: checked on the f32 focal used.
    for (angle, name, size) in [
        (intr.camera_angle_x, "camera_angle_x", w),
        (intr.camera_angle_y, "camera_angle_y", h),
    ] {
        if let Some(a) = angle {
            let f = super::camera::focal_from_angle(size, a as f32);
            if !(a > 0.0 && a < std::f64::consts::PI && f > 0.0 && f.is_finite()) {
                return Err(fmt(format!(
                    "{name} = {a} rad: expected a field of view in (0, π) radians whose focal \
                     length is positive in single precision (got {f} px)"
                )));
            }
        }
    }
    let fx = match (intr.fl_x, intr.camera_angle_x) {
        (Some(f), _) => f,
        (None, Some(a)) => 0.5 * w as f64 / (0.5 * a).tan(),
        (None, None) => return Err(fmt("neither camera_angle_x nor fl_x is given".into())),
    };
    let fy = match (intr.fl_y, intr.camera_angle_y) {
        (Some(f), _) => f,
        (None, Some(a)) => 0.5 * h as f64 / (0.5 * a).tan(),
        (None, None) => fx,
    };
    let cx = intr.cx.unwrap_or(0.5 * w as f64);
    let cy = intr.cy.unwrap_or(0.5 * h as f64);
    for (v, name) in [(fx, "focal x"), (fy, "focal y"), (cx, "cx"), (cy, "cy")] {
        if !v.is_finite() || (name.starts_with("focal") && v <= 0.0) || (v as f32).is_infinite() {
            return Err(fmt(format!("invalid {name} = {v}")));
        }
    }
    if w / k == 0 || h / k == 0 {
        return Err(DataError::BadDownscale {
            path: file,
            factor: k,
            reason: format!("the image is only {w}x{h}"),
        });
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
    if let (None, Some(a)) = (intr.fl_x, intr.camera_angle_x) {
        // The exact f32 formula the scene generator uses, so re-rendering is bit-exact.
        camera.fx = super::camera::focal_from_angle(w, a as f32);
        if intr.fl_y.is_none() && intr.camera_angle_y.is_none() {
            camera.fy = camera.fx;
        }
    }
    let (ow, oh, data) = composite_and_downscale(w, h, &raw, k, bg);
    Ok(Frame {
        file,
        camera: camera.downscaled(k),
        image: RgbaImage {
            width: ow,
            height: oh,
            data,
            had_alpha,
        },
    })
}

/// Checks and converts a 4×4 (or 3×4) camera-to-world matrix given as rows.
fn parse_transform(json: &Path, frame: usize, rows: &[Vec<f64>]) -> Result<Mat4, DataError> {
    let bad = |problem: String| DataError::BadTransform {
        path: json.to_path_buf(),
        frame,
        problem,
    };
    if !(rows.len() == 4 || rows.len() == 3) || rows.iter().any(|r| r.len() != 4) {
        let shape: Vec<usize> = rows.iter().map(|r| r.len()).collect();
        return Err(bad(format!(
            "must be 4x4 (or 3x4) but has row lengths {shape:?}"
        )));
    }
    let mut m = [[0f32; 4]; 4];
    m[3] = [0.0, 0.0, 0.0, 1.0];
    for (r, row) in rows.iter().enumerate() {
        for (c, &v) in row.iter().enumerate() {
            let f = v as f32;
            if !f.is_finite() {
                return Err(bad(format!(
                    "has a non-finite entry {v} at row {r}, column {c}"
                )));
            }
            m[r][c] = f;
        }
    }
    let last = m[3];
    if (last[0].abs() + last[1].abs() + last[2].abs() + (last[3] - 1.0).abs()) > 1e-4 {
        return Err(bad(format!("has last row {last:?}, expected [0, 0, 0, 1]")));
    }
    // glam is column-major: transpose the rows.
    let c2w = Mat4::from_cols_array_2d(&m).transpose();
    let det = glam::Mat3::from_mat4(c2w).determinant();
    if det.abs() < 1e-6 || !det.is_finite() {
        return Err(bad(format!("is singular (rotation determinant {det:e})")));
    }
    Ok(c2w)
}

/// Resolves a frame's `file_path` inside `root` (lexically: `..` may not climb out, absolute
/// paths must lie under `root`), appending `.png` when the path has no such file itself
/// (Blender writes "./train/r_0").
fn resolve_image(
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
    let direct = root.join(&clean);
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
