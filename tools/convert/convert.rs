//! Converts a NeRF-synthetic dataset into the COLMAP (text or binary), IDR and instant-ngp /
//! nerfstudio layouts with exact poses, so the loaders can be checked without downloading
//! anything: same images (RGB in `images/` or `image/`, the alpha channel as a grey mask in
//! `masks/` or `mask/`; for `transforms.json` optionally as a phone's OPENCV lens would have
//! imaged them, [`PHONE_LENS`]), same cameras,
//! the original train/val/test split in `split.json`, and a scene box that the loaders reproduce
//! (COLMAP: the box's corners shrunk by the loader's margin as the sparse points; IDR: the box as
//! `scale_mat`). Used by `cargo run --release --example convert_scene` and by the data tests.

use alphasurf::data::colmap::BOX_MARGIN;
use alphasurf::data::distortion::{distort, Distortion, Pinhole};
use alphasurf::data::{Camera, Dataset, LoadOptions, Split};
use alphasurf::grid::npz;
use anyhow::{ensure, Context, Result};
use glam::{DMat3, DMat4, DQuat, DVec3, DVec4};
use std::fmt::Write as _;
use std::path::Path;

/// The lens of the phone capture in issue 41 (1080×1920, OPENCV): what `transforms.json` with
/// distortion images through.
pub const PHONE_LENS: Distortion = Distortion::OpenCv {
    k1: 0.058,
    k2: -0.081,
    k3: 0.0,
    p1: -0.00098,
    p2: 0.00016,
};

/// A target layout.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Target {
    /// One `transforms.json` (instant-ngp / nerfstudio) with `fl_x/fl_y/cx/cy/w/h`, per-frame
    /// `mask_path`, images and masks as this lens images them (OPENCV) and its coefficients in
    /// the file.
    InstantNgp(Distortion),
    /// LLFF: `poses_bounds.npy` (rows in the images' name order), `images/`, `masks/`.
    Llff,
    /// `sparse/0/*.txt`.
    ColmapText,
    /// `sparse/0/*.bin`.
    ColmapBinary,
    /// `cameras_sphere.npz`, `image/`, `mask/`.
    Idr,
}

/// One view of the source: its name in the target, split, camera and straight-alpha pixels.
struct Source {
    name: String,
    split: String,
    frame_file: std::path::PathBuf,
    c2w_cv: DMat4,
    k: [f64; 4],
    size: (u32, u32),
}

/// Converts the NeRF-synthetic dataset `src` into `target` at `dst` (created; must not exist).
pub fn convert(src: &Path, dst: &Path, target: Target) -> Result<()> {
    let ds = Dataset::load(src, &LoadOptions::default())?;
    ensure!(!dst.exists(), "{} exists already", dst.display());
    let splits: Vec<&Split> = ds.splits();
    let mut views = Vec::new();
    let mut cameras = Vec::new();
    for s in &splits {
        for f in &s.frames {
            let i = views.len();
            let stem = f.file.file_stem().unwrap().to_string_lossy();
            let c = &f.camera;
            cameras.push(*c);
            views.push(Source {
                name: match target {
                    Target::Idr => format!("{i:06}.png"),
                    _ => format!("{}_{stem}.png", s.name),
                },
                split: s.name.clone(),
                frame_file: f.file.clone(),
                // OpenGL → OpenCV axes: flip the camera's Y and Z.
                c2w_cv: c.c2w.as_dmat4() * DMat4::from_diagonal(DVec4::new(1.0, -1.0, -1.0, 1.0)),
                k: [c.fx as f64, c.fy as f64, c.cx as f64, c.cy as f64],
                size: (c.width, c.height),
            });
        }
    }
    let (img_dir, mask_dir) = match target {
        Target::Idr => ("image", "mask"),
        _ => ("images", "masks"),
    };
    std::fs::create_dir_all(dst.join(img_dir))?;
    std::fs::create_dir_all(dst.join(mask_dir))?;
    let lens = match target {
        Target::InstantNgp(lens) => lens,
        _ => Distortion::None,
    };
    for (i, (v, camera)) in views.iter().zip(&cameras).enumerate() {
        let mut rgba = image::open(&v.frame_file)
            .with_context(|| v.frame_file.display().to_string())?
            .to_rgba8();
        let (w, h) = rgba.dimensions();
        if !lens.is_identity() {
            let raw = distort(w, h, rgba.as_raw(), &Pinhole::of(camera), &lens);
            rgba = image::RgbaImage::from_raw(w, h, raw).context("distorted image")?;
        }
        let rgb = image::RgbImage::from_fn(w, h, |x, y| {
            let p = rgba.get_pixel(x, y).0;
            image::Rgb([p[0], p[1], p[2]])
        });
        let alpha =
            image::GrayImage::from_fn(w, h, |x, y| image::Luma([rgba.get_pixel(x, y).0[3]]));
        rgb.save(dst.join(img_dir).join(&v.name))?;
        let mask_name = match target {
            Target::Idr => format!("{i:03}.png"),
            _ => v.name.clone(),
        };
        alpha.save(dst.join(mask_dir).join(mask_name))?;
    }
    // Split files name views as the layout does: instant-ngp by their path in the dataset.
    let names = |split: &str| -> Vec<String> {
        views
            .iter()
            .filter(|v| v.split == split)
            .map(|v| match target {
                Target::InstantNgp(_) => format!("{img_dir}/{}", v.name),
                _ => v.name.clone(),
            })
            .collect()
    };
    let mut split = serde_json::json!({ "train": names("train"), "test": names("test") });
    if ds.val_split.is_some() {
        split["val"] = names("val").into();
    }
    std::fs::write(
        dst.join("split.json"),
        serde_json::to_string_pretty(&split)?,
    )?;
    let (lo, hi) = ds.scene.blender_bounds();
    let (centre, half) = ((lo + hi).as_dvec3() * 0.5, (hi - lo).x as f64 * 0.5);
    match target {
        Target::Idr => write_idr(dst, &views, centre, half),
        Target::InstantNgp(_) => write_transforms(dst, &views, &cameras, &lens),
        Target::Llff => write_poses_bounds(dst, &views, &cameras, centre, half),
        _ => {
            let corners: Vec<DVec3> = (0..8)
                .map(|c| {
                    let s = DVec3::new(
                        if c & 1 == 0 { -1.0 } else { 1.0 },
                        if c & 2 == 0 { -1.0 } else { 1.0 },
                        if c & 4 == 0 { -1.0 } else { 1.0 },
                    );
                    centre + s * (half / BOX_MARGIN)
                })
                .collect();
            let sparse = dst.join("sparse").join("0");
            std::fs::create_dir_all(&sparse)?;
            if target == Target::ColmapText {
                write_colmap_text(&sparse, &views, &corners)
            } else {
                write_colmap_binary(&sparse, &views, &corners)
            }
        }
    }
}

/// `transforms.json`: the first camera's intrinsics and the lens at the top level, each frame's
/// pose (OpenGL camera-to-world), image and mask.
fn write_transforms(
    dst: &Path,
    views: &[Source],
    cameras: &[Camera],
    lens: &Distortion,
) -> Result<()> {
    let c = &cameras[0];
    let mut doc = serde_json::json!({
        "fl_x": c.fx, "fl_y": c.fy, "cx": c.cx, "cy": c.cy, "w": c.width, "h": c.height,
        "camera_model": "OPENCV",
    });
    if let Distortion::OpenCv { k1, k2, k3, p1, p2 } = *lens {
        for (k, v) in [("k1", k1), ("k2", k2), ("k3", k3), ("p1", p1), ("p2", p2)] {
            doc[k] = v.into();
        }
    }
    let frames: Vec<serde_json::Value> = views
        .iter()
        .zip(cameras)
        .map(|(v, c)| {
            let rows: Vec<[f32; 4]> = (0..4).map(|r| c.c2w.row(r).to_array()).collect();
            serde_json::json!({
                "file_path": format!("images/{}", v.name),
                "mask_path": format!("masks/{}", v.name),
                "transform_matrix": rows,
            })
        })
        .collect();
    doc["frames"] = frames.into();
    std::fs::write(
        dst.join("transforms.json"),
        serde_json::to_string_pretty(&doc)?,
    )?;
    Ok(())
}

/// `poses_bounds.npy`: per image in name order, [down, right, back, centre | H, W, focal] row-major
/// and the near and far depths of the box's bounding sphere.
fn write_poses_bounds(
    dst: &Path,
    views: &[Source],
    cameras: &[Camera],
    centre: DVec3,
    half: f64,
) -> Result<()> {
    let mut order: Vec<usize> = (0..views.len()).collect();
    order.sort_by(|&a, &b| views[a].name.cmp(&views[b].name));
    let mut rows = Vec::with_capacity(17 * views.len());
    for i in order {
        let c = &cameras[i];
        let m = c.c2w.as_dmat4();
        let cols = [-m.y_axis, m.x_axis, m.z_axis, m.w_axis];
        let hwf = [c.height as f64, c.width as f64, c.fx as f64];
        for r in 0..3 {
            rows.extend(cols.iter().map(|col| col[r]));
            rows.push(hwf[r]);
        }
        let d = (m.w_axis.truncate() - centre).length();
        let reach = half * 3f64.sqrt();
        rows.extend([(d - reach).max(0.01 * d), d + reach]);
    }
    use npyz::WriterBuilder;
    let mut bytes = Vec::new();
    let mut w = npyz::WriteOptions::<f64>::new()
        .default_dtype()
        .shape(&[views.len() as u64, 17])
        .writer(&mut bytes)
        .begin_nd()?;
    w.extend(rows)?;
    w.finish()?;
    std::fs::write(dst.join("poses_bounds.npy"), bytes)?;
    Ok(())
}

/// World-to-camera (R as a unit quaternion w, x, y, z; t) of an OpenCV camera-to-world.
fn w2c(v: &Source) -> ([f64; 4], DVec3) {
    let rot = DMat3::from_mat4(v.c2w_cv).transpose();
    let q = DQuat::from_mat3(&rot).normalize();
    let t = -(rot * v.c2w_cv.w_axis.truncate());
    ([q.w, q.x, q.y, q.z], t)
}

fn write_colmap_text(sparse: &Path, views: &[Source], corners: &[DVec3]) -> Result<()> {
    let (mut cams, mut imgs, mut pts) = (String::new(), String::new(), String::new());
    cams += "# CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n";
    imgs += "# IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n# POINTS2D[] as (X, Y, POINT3D_ID)\n";
    for (i, v) in views.iter().enumerate() {
        let [fx, fy, cx, cy] = v.k;
        writeln!(
            cams,
            "{} PINHOLE {} {} {fx:?} {fy:?} {cx:?} {cy:?}",
            i + 1,
            v.size.0,
            v.size.1
        )?;
        let (q, t) = w2c(v);
        writeln!(
            imgs,
            "{} {:?} {:?} {:?} {:?} {:?} {:?} {:?} {} {}\n",
            i + 1,
            q[0],
            q[1],
            q[2],
            q[3],
            t.x,
            t.y,
            t.z,
            i + 1,
            v.name
        )?;
    }
    for (i, p) in corners.iter().enumerate() {
        writeln!(
            pts,
            "{} {:?} {:?} {:?} 128 128 128 0.0",
            i + 1,
            p.x,
            p.y,
            p.z
        )?;
    }
    std::fs::write(sparse.join("cameras.txt"), cams)?;
    std::fs::write(sparse.join("images.txt"), imgs)?;
    std::fs::write(sparse.join("points3D.txt"), pts)?;
    Ok(())
}

fn write_colmap_binary(sparse: &Path, views: &[Source], corners: &[DVec3]) -> Result<()> {
    let (mut cams, mut imgs, mut pts) = (Vec::new(), Vec::new(), Vec::new());
    cams.extend((views.len() as u64).to_le_bytes());
    imgs.extend((views.len() as u64).to_le_bytes());
    for (i, v) in views.iter().enumerate() {
        let id = (i + 1) as i32;
        cams.extend(id.to_le_bytes());
        cams.extend(1i32.to_le_bytes()); // PINHOLE
        cams.extend((v.size.0 as u64).to_le_bytes());
        cams.extend((v.size.1 as u64).to_le_bytes());
        v.k.iter().for_each(|x| cams.extend(x.to_le_bytes()));
        let (q, t) = w2c(v);
        imgs.extend(id.to_le_bytes());
        q.iter()
            .chain(&t.to_array())
            .for_each(|x| imgs.extend(x.to_le_bytes()));
        imgs.extend(id.to_le_bytes());
        imgs.extend(v.name.as_bytes());
        imgs.push(0);
        imgs.extend(0u64.to_le_bytes());
    }
    pts.extend((corners.len() as u64).to_le_bytes());
    for (i, p) in corners.iter().enumerate() {
        pts.extend((i as u64 + 1).to_le_bytes());
        p.to_array()
            .iter()
            .for_each(|x| pts.extend(x.to_le_bytes()));
        pts.extend([128u8; 3]);
        pts.extend(0f64.to_le_bytes());
        pts.extend(0u64.to_le_bytes());
    }
    std::fs::write(sparse.join("cameras.bin"), cams)?;
    std::fs::write(sparse.join("images.bin"), imgs)?;
    std::fs::write(sparse.join("points3D.bin"), pts)?;
    Ok(())
}

/// `world_mat_i` = K·[R|t] (IDR's pixel centres at integers: K's principal point is ours − 0.5)
/// and `scale_mat_i` mapping the box's cube to [−1, 1]³.
fn write_idr(dst: &Path, views: &[Source], centre: DVec3, half: f64) -> Result<()> {
    let scale = DMat4::from_cols(
        DVec4::new(half, 0.0, 0.0, 0.0),
        DVec4::new(0.0, half, 0.0, 0.0),
        DVec4::new(0.0, 0.0, half, 0.0),
        centre.extend(1.0),
    );
    let rows = |m: DMat4| m.transpose().to_cols_array();
    npz::write_atomic(&dst.join("cameras_sphere.npz"), |z| {
        for (i, v) in views.iter().enumerate() {
            let [fx, fy, cx, cy] = v.k;
            let k = DMat4::from_cols(
                DVec4::new(fx, 0.0, 0.0, 0.0),
                DVec4::new(0.0, fy, 0.0, 0.0),
                DVec4::new(cx - 0.5, cy - 0.5, 1.0, 0.0),
                DVec4::W,
            );
            let world = k * v.c2w_cv.inverse();
            z.array(&format!("world_mat_{i}"), &[4, 4], &rows(world))?;
            z.array(&format!("scale_mat_{i}"), &[4, 4], &rows(scale))?;
        }
        Ok(())
    })
}
