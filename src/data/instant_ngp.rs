//! The instant-ngp / nerfstudio layout: one `transforms.json` in the [`super::transforms`] schema
//! (intrinsics shared or per frame, PINHOLE or OPENCV lens undistorted on load, fisheye and
//! unapplied coefficients refused by name), images named by `file_path` (`.jpg`/`.png`, turned
//! upright by their EXIF orientation), nerfstudio's per-frame `mask_path` (alpha from the mask's
//! first channel). Without a `split.json` every 8th image by name is held out (as for COLMAP).
//!
//! The scene box is the foreground box found from the cameras ([`super::foreground`]) and, when
//! the file names one (nerfstudio's `ply_file_path`), its sparse points; inside instant-ngp's
//! `aabb_scale` box when the file has one (instant-ngp maps world p to 0.33·p + 0.5, or its
//! `scale`/`offset`, with the axes cycled; the box is [0.5 − a/2, 0.5 + a/2]³ there).
//! nerfstudio's `applied_transform` (COLMAP's frame → the file's) is checked; poses, the box and
//! every output stay in the file's frame.
//!
//! `--downscale k` reads `images_k/` (and `masks_k/`) when every frame's file lies in `images/`
//! (and mask in `masks/`) and those folders exist, as nerfstudio writes them.

use super::aabb::Aabb;
use super::error::DataError;
use super::foreground::{self, ForegroundBox};
use super::image::image_size;
use super::scene_box::SceneBox;
use super::transforms::{
    parse_matrix, parse_transform, read_json, relative_path, resolve_image, FrameJson, Intrinsics,
};
use super::views::{self, Folders, Posed, View};
use glam::DVec3;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// The file this layout is detected by.
pub const FILE: &str = "transforms.json";

/// instant-ngp's default world → unit-cube scale and offset.
const NGP_SCALE: f64 = 0.33;
const NGP_OFFSET: [f64; 3] = [0.5; 3];

#[derive(Deserialize)]
struct TransformsFile {
    #[serde(flatten)]
    intr: Intrinsics,
    frames: Vec<FrameJson>,
    aabb_scale: Option<f64>,
    scale: Option<f64>,
    offset: Option<[f64; 3]>,
    applied_transform: Option<Vec<Vec<f64>>>,
    ply_file_path: Option<String>,
}

/// The posed views and scene box of the `transforms.json` dataset `root` (`k`: the requested
/// downscale, which picks the image folder); of the images only their headers are read when the
/// file gives no `w`/`h`.
pub fn posed(root: &Path, k: u32) -> Result<Posed, DataError> {
    let json = root.join(FILE);
    let file: TransformsFile = read_json(&json)?;
    let format = |msg: String| DataError::Format {
        path: json.clone(),
        msg,
    };
    if file.frames.is_empty() {
        return Err(format("no frames".into()));
    }
    if let Some(rows) = &file.applied_transform {
        parse_matrix(rows).map_err(|p| format(format!("applied_transform {p}")))?;
    }
    let bounds = aabb(&file).map_err(&format)?;
    let mut views = Vec::with_capacity(file.frames.len());
    let mut rel_masks = Vec::with_capacity(file.frames.len());
    for (i, fr) in file.frames.into_iter().enumerate() {
        let c2w = parse_transform(&json, i, &fr.transform_matrix)?;
        let image = resolve_image(root, &json, i, &fr.file_path)?;
        let intr = fr.intr.or(&file.intr);
        let distortion = intr.distortion(&json, i)?;
        let (w, h) = match intr.size(&json, i)? {
            Some(size) => size,
            None => image_size(&image)?,
        };
        let camera = intr.camera(&json, i, c2w, w, h)?;
        let mask = fr
            .mask_path
            .as_deref()
            .map(|m| relative_path(root, &json, i, m))
            .transpose()?;
        rel_masks.push(mask);
        views.push(View {
            name: image
                .strip_prefix(root)
                .unwrap_or(&image)
                .to_string_lossy()
                .into_owned(),
            file: image,
            mask: None,
            camera,
            distortion,
        });
    }
    let folders = prescaled_folders(root, k, &views, &rel_masks);
    // `name` is the image's path relative to the root; `images_k/` replaces `images/`.
    let place = |rel: &Path, dir: &str, folder: Option<&Path>| match (folder, rel.strip_prefix(dir))
    {
        (Some(f), Ok(rest)) if folders.prescaled > 1 => f.join(rest),
        _ => root.join(rel),
    };
    for (v, mask) in views.iter_mut().zip(rel_masks) {
        v.mask = mask.map(|m| place(&m, "masks", folders.masks.as_deref()));
        v.file = place(Path::new(&v.name), "images", Some(&folders.images));
    }
    let points = match &file.ply_file_path {
        Some(p) => sparse_points(root, &json, p)?,
        None => Vec::new(),
    };
    let cameras: Vec<_> = views.iter().map(|v| v.camera).collect();
    let foreground = foreground::find(&cameras, &points).map(|fg| match bounds {
        Some(b) => ForegroundBox {
            bounds: Aabb::new(
                fg.bounds.lo().clamp(b.lo(), b.hi()),
                fg.bounds.hi().clamp(b.lo(), b.hi()),
            ),
            how: format!("{}; inside aabb_scale's box", fg.how),
            ..fg
        },
        None => fg,
    });
    let scene = match (&foreground, bounds) {
        (Some(fg), _) => fg.bounds.scene_box(),
        (None, Some(b)) => b.scene_box(),
        (None, None) => SceneBox::default(),
    };
    Ok(Posed {
        views,
        folders,
        source: json,
        scene,
        foreground,
        nearest: None,
    })
}

/// The folders `images/` and `masks/` (or their `_k` versions) when every frame's image lies in
/// `images/` and every mask in `masks/`; else the dataset root at full resolution.
fn prescaled_folders(root: &Path, k: u32, views: &[View], masks: &[Option<PathBuf>]) -> Folders {
    let under = |p: &Path, dir: &str| p.components().next().is_some_and(|c| c.as_os_str() == dir);
    let images_ok = views.iter().all(|v| under(Path::new(&v.name), "images"));
    let masks_ok = masks
        .iter()
        .all(|m| m.as_deref().is_none_or(|m| under(m, "masks")));
    if images_ok && masks_ok {
        let mut f = views::folders(root, "images", "masks", k);
        if masks.iter().all(Option::is_none) {
            f.masks = None;
        }
        f
    } else {
        Folders {
            images: root.to_path_buf(),
            masks: masks
                .iter()
                .any(Option::is_some)
                .then(|| root.to_path_buf()),
            prescaled: 1,
        }
    }
}

/// The sparse points of nerfstudio's `ply_file_path`, in the file's frame.
fn sparse_points(root: &Path, json: &Path, ply: &str) -> Result<Vec<[f64; 3]>, DataError> {
    let format = |msg: String| DataError::Format {
        path: json.to_path_buf(),
        msg: format!("ply_file_path '{ply}': {msg}"),
    };
    // The frame-independent check of `relative_path`: inside the dataset directory.
    let rel = relative_path(root, json, 0, ply)
        .map_err(|_| format("does not name a file inside the dataset directory".into()))?;
    let points = crate::io::read_points(&root.join(rel)).map_err(|e| format(format!("{e:#}")))?;
    Ok(points.iter().map(|p| p.map(f64::from)).collect())
}

/// instant-ngp's `aabb_scale` box in the file's world units, if the file has one.
fn aabb(file: &TransformsFile) -> Result<Option<Aabb>, String> {
    let Some(a) = file.aabb_scale else {
        return Ok(None);
    };
    let s = file.scale.unwrap_or(NGP_SCALE);
    let o = file.offset.unwrap_or(NGP_OFFSET);
    if !(a > 0.0 && a.is_finite() && s > 0.0 && s.is_finite() && o.iter().all(|v| v.is_finite())) {
        return Err(format!(
            "aabb_scale {a}, scale {s}, offset {o:?}: expected positive finite values"
        ));
    }
    // instant-ngp's unit-cube axes (x, y, z) are the world's (y, z, x).
    let centre = DVec3::new(0.5 - o[2], 0.5 - o[0], 0.5 - o[1]) / s;
    let half = DVec3::splat(0.5 * a / s);
    Ok(Some(Aabb::new(
        (centre - half).as_vec3(),
        (centre + half).as_vec3(),
    )))
}
