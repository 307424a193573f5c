//! The IDR layout (DTU as IDR and NeuS ship it): `cameras_sphere.npz` with `world_mat_i` (the
//! 4×4 projection K·[R|t] of image i) and `scale_mat_i` (normalised → world: a uniform scale s
//! and a translation c placing the object in the unit sphere), `image/` and optional `mask/`
//! (alpha from the first channel), both matched to i by sorted file name.
//!
//! Each camera is the standard decomposition of P = world_mat·scale_mat (RQ: K upper triangular
//! with a positive diagonal, R a rotation), i.e. in the normalised frame; its centre is taken back
//! to world units (s·C + c), so poses are the dataset's own, and the scene box is the unit
//! sphere's cube: scale 1/s, centre c/s, radius 1. IDR renders pixel (x, y) through image point
//! (x, y) (pixel centres at integers, OpenCV); ours are at +0.5, so cx = K₀₂ + 0.5, cy = K₁₂ + 0.5.

use super::camera::Camera;
use super::distortion::Distortion;
use super::error::DataError;
use super::image::image_size;
use super::scene_box::SceneBox;
use super::views::{self, Posed, View};
use crate::grid::npz::NpzReader;
use glam::{DMat3, DMat4, DVec3, DVec4, Mat4};
use std::path::{Path, PathBuf};

/// The camera file of the layout.
pub const CAMERAS: &str = "cameras_sphere.npz";

/// Largest |skew| / fx accepted (the skew is dropped; our cameras have none).
pub const MAX_SKEW: f64 = 1e-3;

/// The posed views and scene box of the IDR dataset `root` (`k`: the requested downscale, which
/// picks the image folder); of the images only their sizes are read (headers).
pub fn posed(root: &Path, k: u32) -> Result<Posed, DataError> {
    let npz_path = root.join(CAMERAS);
    let fail = |msg: String| DataError::Format {
        path: npz_path.clone(),
        msg,
    };
    let mut npz = NpzReader::open(&npz_path).map_err(|e| fail(format!("{e:#}")))?;
    let n = npz
        .names()
        .iter()
        .filter(|s| s.strip_prefix("world_mat_").is_some_and(is_index))
        .count();
    let mut mat = |name: String| -> Result<DMat4, DataError> {
        let (shape, v) = npz.read_f64(&name).map_err(|e| fail(format!("{e:#}")))?;
        if shape != [4, 4] {
            return Err(fail(format!(
                "'{name}' has shape {shape:?}, expected [4, 4]"
            )));
        }
        Ok(DMat4::from_cols_array(&v.try_into().unwrap()).transpose())
    };
    let mut pairs = Vec::with_capacity(n);
    for i in 0..n {
        pairs.push((
            mat(format!("world_mat_{i}"))?,
            mat(format!("scale_mat_{i}"))?,
        ));
    }
    let folders = views::folders(root, "image", "mask", k);
    let images = list_images(&folders.images)?;
    let masks = folders.masks.as_deref().map(list_images).transpose()?;
    for (dir, count) in [(&folders.images, images.len())].into_iter().chain(
        masks
            .as_ref()
            .map(|m| (folders.masks.as_ref().unwrap(), m.len())),
    ) {
        if count != n {
            return Err(DataError::CountMismatch {
                path: dir.clone(),
                msg: format!("{count} images but {} poses {n} (world_mat_0..)", CAMERAS),
            });
        }
    }
    if n == 0 {
        return Err(fail("no world_mat_0, world_mat_1, … arrays".into()));
    }
    let (s, c) = similarity(&npz_path, &pairs[0].1, 0)?;
    let mut posed = Vec::with_capacity(n);
    for (i, (world, scale)) in pairs.iter().enumerate() {
        let name = file_name(&images[i]);
        if similarity(&npz_path, scale, i)? != (s, c) {
            return Err(fail(format!(
                "scale_mat_{i} differs from scale_mat_0: the loader needs one normalisation"
            )));
        }
        let bad = |problem: String| DataError::BadPose {
            path: npz_path.clone(),
            image: name.clone(),
            problem: format!("world_mat_{i}: {problem}"),
        };
        let p = *world * *scale;
        let (kmat, c2w_cv, centre) = decompose(&p).map_err(bad)?;
        let fx = kmat.x_axis.x;
        let skew = kmat.y_axis.x;
        if skew.abs() > MAX_SKEW * fx {
            return Err(bad(format!("skew {skew} px is not negligible (fx {fx})")));
        }
        // The normalised-frame centre back to world units; the rotation is the same.
        let centre = s * centre + c;
        let (w, h) = image_size(&images[i])?;
        let axes = [c2w_cv.x_axis, -c2w_cv.y_axis, -c2w_cv.z_axis];
        let f = |v: DVec3| v.as_vec3().extend(0.0);
        posed.push(View {
            name,
            file: images[i].clone(),
            mask: masks.as_ref().map(|m| m[i].clone()),
            camera: Camera {
                c2w: Mat4::from_cols(
                    f(axes[0]),
                    f(axes[1]),
                    f(axes[2]),
                    centre.as_vec3().extend(1.0),
                ),
                fx: fx as f32,
                fy: kmat.y_axis.y as f32,
                cx: (kmat.z_axis.x + 0.5) as f32,
                cy: (kmat.z_axis.y + 0.5) as f32,
                width: w,
                height: h,
            },
            distortion: Distortion::None,
        });
    }
    let scene = SceneBox {
        scale: (1.0 / s) as f32,
        centre: (c / s).as_vec3(),
        radius: 1.0,
        ndc: None,
    };
    Ok(Posed {
        views: posed,
        folders,
        source: npz_path,
        scene,
        foreground: None,
        nearest: None,
    })
}

fn is_index(s: &str) -> bool {
    !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit())
}

fn file_name(p: &Path) -> String {
    p.file_name()
        .map_or_else(String::new, |s| s.to_string_lossy().into_owned())
}

/// The PNG/JPEG files of `dir`, sorted by name.
pub(super) fn list_images(dir: &Path) -> Result<Vec<PathBuf>, DataError> {
    let entries = std::fs::read_dir(dir).map_err(|e| DataError::Format {
        path: dir.to_path_buf(),
        msg: format!("cannot list the image folder: {e}"),
    })?;
    let mut v: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            let ext = p.extension().map(|e| e.to_ascii_lowercase());
            ext.is_some_and(|e| e == "png" || e == "jpg" || e == "jpeg")
        })
        .collect();
    v.sort();
    Ok(v)
}

/// (s, c) of a `scale_mat` that is s·I with translation c, or an error.
fn similarity(path: &Path, m: &DMat4, i: usize) -> Result<(f64, DVec3), DataError> {
    let s = m.x_axis.x;
    let expect = DMat4::from_cols(
        DVec4::new(s, 0.0, 0.0, 0.0),
        DVec4::new(0.0, s, 0.0, 0.0),
        DVec4::new(0.0, 0.0, s, 0.0),
        m.w_axis.truncate().extend(1.0),
    );
    let off = (*m - expect)
        .to_cols_array()
        .iter()
        .fold(0f64, |a, v| a.max(v.abs()));
    if !(s > 0.0 && m.is_finite() && off <= 1e-9 * s) {
        return Err(DataError::Format {
            path: path.to_path_buf(),
            msg: format!(
                "scale_mat_{i} is not a uniform scale and a translation (rows {:?})",
                m.transpose().to_cols_array_2d()
            ),
        });
    }
    Ok((s, m.w_axis.truncate()))
}

/// K (normalised, K₂₂ = 1), camera-to-world rotation (OpenCV axes) and camera centre of the
/// projection P (its top three rows), by RQ decomposition of P's left 3×3 block.
fn decompose(p: &DMat4) -> Result<(DMat3, DMat3, DVec3), String> {
    if !p.is_finite() {
        return Err("non-finite entries".into());
    }
    let row = |r: usize| DVec3::new(p.x_axis[r], p.y_axis[r], p.z_axis[r]);
    let (mut m1, mut m2, mut m3) = (row(0), row(1), row(2));
    let mut p4 = DVec3::new(p.w_axis[0], p.w_axis[1], p.w_axis[2]);
    let det = DMat3::from_cols(m1, m2, m3).determinant();
    // Finite P, so det is finite: a comparison decides.
    if det.abs() <= 1e-12 * m3.length().powi(3) || m3.length() == 0.0 {
        return Err(format!("singular projection (determinant {det:e})"));
    }
    if det < 0.0 {
        // P is defined up to scale, sign included: the positive one has a rotation for R.
        (m1, m2, m3, p4) = (-m1, -m2, -m3, -p4);
    }
    let k33 = m3.length();
    let r3 = m3 / k33;
    let k23 = m2.dot(r3);
    let r2 = m2 - k23 * r3;
    let k22 = r2.length();
    let r2 = r2 / k22;
    let (k13, k12) = (m1.dot(r3), m1.dot(r2));
    let r1 = m1 - k13 * r3 - k12 * r2;
    let k11 = r1.length();
    let r1 = r1 / k11;
    // K's columns, normalised by K₂₂.
    let k = DMat3::from_cols(
        DVec3::new(k11, 0.0, 0.0),
        DVec3::new(k12, k22, 0.0),
        DVec3::new(k13, k23, k33),
    ) * (1.0 / k33);
    // Rows r1..r3 of the world-to-camera rotation are the camera-to-world's columns.
    let c2w = DMat3::from_cols(r1, r2, r3);
    let m = DMat3::from_cols(m1, m2, m3).transpose();
    let centre = -(m.inverse() * p4);
    Ok((k, c2w, centre))
}
