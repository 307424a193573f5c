//! The NeRF-synthetic ("Blender") layout: `transforms_{train,val,test}.json` (val falls back to
//! test) in the [`super::transforms`] schema (`camera_angle_x` or `fl_x`/`fl_y`/`cx`/`cy`/`w`/`h`,
//! top level or per frame; an OPENCV lens undistorted on load), RGBA/RGB PNG and JPEG images
//! loaded in parallel, composited on the background, optionally box-downscaled, and held as 8-bit
//! RGBA.

use super::distortion::{undistort, Pinhole};
use super::error::DataError;
use super::image::{composite_and_downscale, decode_file, RgbaImage};
use super::split::{Frame, Split};
use super::transforms::{parse_transform, read_json, resolve_image, FrameJson, Intrinsics};
use glam::Mat4;
use rayon::prelude::*;
use serde::Deserialize;
use std::path::{Path, PathBuf};

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

#[derive(Deserialize)]
struct TransformsJson {
    #[serde(flatten)]
    intr: Intrinsics,
    frames: Vec<FrameJson>,
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
    let parsed: TransformsJson = read_json(&json)?;
    if parsed.frames.is_empty() {
        return Err(DataError::EmptySplit {
            path: json,
            split: name.into(),
        });
    }
    let mut jobs = Vec::with_capacity(parsed.frames.len());
    for (i, fr) in parsed.frames.into_iter().enumerate() {
        let c2w = parse_transform(&json, i, &fr.transform_matrix)?;
        let file = resolve_image(root, &json, i, &fr.file_path)?;
        let intr = fr.intr.or(&parsed.intr);
        intr.distortion(&json, i)?;
        jobs.push((file, c2w, intr));
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
    let camera = intr.camera(json, i, c2w, w, h)?;
    let distortion = intr.distortion(json, i)?;
    if w / k == 0 || h / k == 0 {
        return Err(DataError::BadDownscale {
            path: file,
            factor: k,
            reason: format!("the image is only {w}x{h}"),
        });
    }
    let raw = if distortion.is_identity() {
        raw
    } else {
        undistort(w, h, &raw, &Pinhole::of(&camera), &distortion)
    };
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
