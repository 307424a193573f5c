//! The loaders on hand-made datasets: nerfstudio intrinsics, RGB PNG and JPEG, file paths with
//! and without extensions, downscaling, the rays of a whole view; the fixture converted to the
//! COLMAP and IDR layouts, the held-out split, undistortion.

use crate::data_common::convert::Target;
use crate::data_common::*;
use alphasurf::data::distortion::Distortion;
use alphasurf::data::{view_rays, Dataset, Layout, LoadOptions, SceneBox};
use glam::Vec3;
use serde_json::json;

#[test]
fn nerfstudio_intrinsics_top_level_and_per_frame() {
    let d = tempfile::tempdir().unwrap();
    write_dataset(d.path(), 2, 8, 6);
    let mut v = read_json(d.path(), "train");
    let obj = v.as_object_mut().unwrap();
    obj.remove("camera_angle_x");
    for (k, x) in [
        ("fl_x", 10.0),
        ("fl_y", 11.0),
        ("cx", 3.5),
        ("cy", 2.5),
        ("w", 8.0),
        ("h", 6.0),
    ] {
        obj.insert(k.into(), json!(x));
    }
    v["frames"][1]["fl_x"] = json!(20.0);
    write_json(d.path(), "train", &v);
    let ds = Dataset::load(d.path(), &LoadOptions::default()).unwrap();
    let c0 = ds.train.frames[0].camera;
    assert_eq!((c0.fx, c0.fy, c0.cx, c0.cy), (10.0, 11.0, 3.5, 2.5));
    assert_eq!(ds.train.frames[1].camera.fx, 20.0);
    // The ray through (cx, cy) is the optical axis; through (cx + fx, cy) it is 45° to the right.
    let (_, d0) = c0.ray_at(3.5, 2.5);
    assert!((d0 - c0.forward()).length() < 1e-6);
    let (_, d1) = c0.ray_at(13.5, 2.5);
    let right = c0.c2w.x_axis.truncate();
    assert!(
        (d1.dot(c0.forward()) - 0.5f32.sqrt()).abs() < 1e-6
            && (d1.dot(right) - 0.5f32.sqrt()).abs() < 1e-6
    );
    // Downscaled by 2: everything halves.
    let ds2 = Dataset::load(
        d.path(),
        &LoadOptions {
            downscale: 2,
            ..Default::default()
        },
    )
    .unwrap();
    let c = ds2.train.frames[0].camera;
    assert_eq!(
        (c.fx, c.fy, c.cx, c.cy, c.width, c.height),
        (5.0, 5.5, 1.75, 1.25, 4, 3)
    );
}

#[test]
fn rgb_png_and_jpeg_with_extensions() {
    let d = tempfile::tempdir().unwrap();
    write_dataset(d.path(), 2, 8, 6);
    let rgb = image::RgbImage::from_fn(8, 6, |x, y| image::Rgb([x as u8 * 20, y as u8 * 30, 200]));
    rgb.save(d.path().join("train/a.png")).unwrap();
    image::DynamicImage::ImageRgb8(rgb.clone())
        .save(d.path().join("train/b.jpg"))
        .unwrap();
    let mut v = read_json(d.path(), "train");
    v["frames"][0]["file_path"] = json!("train/a.png");
    v["frames"][1]["file_path"] = json!(d.path().join("train/b.jpg").to_str().unwrap()); // absolute, inside
    write_json(d.path(), "train", &v);
    let ds = Dataset::load(d.path(), &LoadOptions::default()).unwrap();
    let (a, b) = (&ds.train.frames[0].image, &ds.train.frames[1].image);
    assert!(!a.had_alpha && !b.had_alpha);
    assert_eq!(a.pixel(3, 2), [60, 60, 200, 255]);
    let pb = b.pixel(3, 2);
    assert!(pb[3] == 255 && (pb[2] as i32 - 200).abs() < 25, "{pb:?}");
    let report = alphasurf::data::inspect::inspect(&ds).warnings.join("\n");
    assert!(
        report.contains("2 images have no alpha") || report.contains("2 of 2 images have no alpha"),
        "{report}"
    );
}

#[test]
fn view_rays_cover_the_image_in_row_order() {
    let d = tempfile::tempdir().unwrap();
    write_dataset(d.path(), 1, 8, 6);
    let ds = Dataset::load(d.path(), &LoadOptions::default()).unwrap();
    let b = view_rays(&ds.train, &ds.scene, 0);
    assert_eq!(b.len(), 48);
    let f = &ds.train.frames[0];
    let (o, dir) = f.camera.pixel_ray(5, 3);
    let i = 3 * 8 + 5;
    assert_eq!(Vec3::from_array(b.origins[i]), o * (2.0 / 3.0));
    assert_eq!(Vec3::from_array(b.dirs[i]), dir);
    assert_eq!(b.rgb[i], f.image.rgb(5, 3));
    // A custom scene box scales the origins only.
    let sb = SceneBox {
        scale: 0.5,
        centre: Vec3::new(0.1, 0.0, 0.0),
        radius: 2.0,
        ndc: None,
    };
    let b2 = view_rays(&ds.train, &sb, 0);
    assert_eq!(Vec3::from_array(b2.origins[i]), o * 0.5);
    assert_eq!(
        sb.blender_bounds(),
        (Vec3::new(-3.8, -4.0, -4.0), Vec3::new(4.2, 4.0, 4.0))
    );
}

#[test]
fn cameras_not_looking_at_the_box_are_warned_about() {
    let d = tempfile::tempdir().unwrap();
    write_dataset(d.path(), 2, 8, 6);
    let mut v = read_json(d.path(), "test");
    // Camera at (0, 0, 4) looking along −Z... shifted sideways by 10: its axis misses the box.
    v["frames"][1]["transform_matrix"] =
        json!([[1, 0, 0, 10], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]]);
    write_json(d.path(), "test", &v);
    let ds = Dataset::load(d.path(), &LoadOptions::default()).unwrap();
    let w = alphasurf::data::inspect::inspect(&ds).warnings.join("\n");
    assert!(
        w.contains("test: 1 cameras do not look at the scene box") && w.contains("view 1"),
        "{w}"
    );
}

/// The fixture converted to each layout loads back with the same cameras (pose difference
/// ≤ 1e-5, intrinsics to f32 rounding), byte-identical images, the same splits and scene box
/// (instant-ngp and LLFF: theirs is the one found from the cameras).
#[test]
fn converted_fixture_loads_with_the_same_cameras_images_and_box() {
    let src = fixture();
    let orig = Dataset::load(&src, &LoadOptions::default()).unwrap();
    let ngp = Target::InstantNgp(Distortion::None);
    for target in [
        Target::ColmapText,
        Target::ColmapBinary,
        Target::Idr,
        ngp,
        Target::Llff,
    ] {
        let (_keep, dir) = converted(&src, target);
        let ds = Dataset::load(&dir, &LoadOptions::default()).unwrap();
        let want_layout = match target {
            Target::Idr => matches!(ds.layout, Layout::Idr),
            Target::ColmapText => matches!(ds.layout, Layout::Colmap { binary: false, .. }),
            Target::ColmapBinary => matches!(ds.layout, Layout::Colmap { binary: true, .. }),
            Target::InstantNgp(_) => matches!(ds.layout, Layout::InstantNgp),
            Target::Llff => matches!(ds.layout, Layout::Llff),
        };
        assert!(want_layout, "{target:?}: detected {}", ds.layout);
        let pose = max_pose_difference(&orig, &ds);
        assert!(pose <= 1e-5, "{target:?}: max pose difference {pose:e}");
        for (sa, sb) in orig.splits().iter().zip(ds.splits()) {
            for (fa, fb) in sa.frames.iter().zip(&sb.frames) {
                let (a, b) = (&fa.camera, &fb.camera);
                for (x, y) in [(a.fx, b.fx), (a.fy, b.fy), (a.cx, b.cx), (a.cy, b.cy)] {
                    assert!(
                        (x - y).abs() <= 1e-5 * x.abs(),
                        "{target:?}: {a:?} vs {b:?}"
                    );
                }
                assert_eq!((a.width, a.height), (b.width, b.height));
                assert!(
                    fb.image == fa.image,
                    "{target:?}: {} differs",
                    fb.file.display()
                );
            }
        }
        if target == ngp || target == Target::Llff {
            continue;
        }
        let (s, t) = (orig.scene, ds.scene);
        assert_eq!(s.scale, t.scale, "{target:?}");
        assert!(
            (s.centre - t.centre).abs().max_element() <= 1e-6,
            "{target:?}: {t:?}"
        );
        assert_eq!(s.radius, t.radius, "{target:?}");
    }
}

/// Without a split file, every 8th view by name is held out for testing (LLFF practice).
#[test]
fn colmap_without_split_file_holds_out_every_eighth_view() {
    let src = tempfile::tempdir().unwrap();
    write_dataset(src.path(), 7, 8, 6);
    let (_keep, dir) = converted(src.path(), Target::ColmapBinary);
    std::fs::remove_file(dir.join("split.json")).unwrap();
    let ds = Dataset::load(&dir, &LoadOptions::default()).unwrap();
    let names = |s: &alphasurf::data::Split| -> Vec<String> {
        s.frames
            .iter()
            .map(|f| f.file.file_name().unwrap().to_string_lossy().into_owned())
            .collect()
    };
    let mut all: Vec<String> = names(&ds.train)
        .into_iter()
        .chain(names(&ds.test))
        .collect();
    all.sort();
    assert_eq!(all.len(), 21);
    let test: Vec<String> = all.iter().step_by(8).cloned().collect();
    assert_eq!(names(&ds.test), test);
    assert_eq!(ds.train.frames.len(), 21 - 3);
    assert!(ds.val_split.is_none());
}

/// An OPENCV camera's image, made by sampling a smooth pattern through the lens, comes back
/// undistorted: within 2/255 of the pattern on the ideal pinhole wherever the lens saw it (left
/// distorted, it is up to ~20/255 off at the border).
#[test]
fn colmap_opencv_images_are_undistorted_on_load() {
    let src = tempfile::tempdir().unwrap();
    write_dataset(src.path(), 1, 64, 48);
    let (_keep, dir) = converted(src.path(), Target::ColmapText);
    let d = Distortion::OpenCv {
        k1: -0.3,
        k2: 0.08,
        k3: 0.0,
        p1: 0.002,
        p2: -0.003,
    };
    let (fx, fy, cx, cy) = (70.0, 66.0, 31.0, 25.0);
    // A smooth pattern on the ideal image plane, in [0, 255].
    let pattern = |x: f64, y: f64| 127.5 + 100.0 * (8.0 * x).sin() * (6.0 * y + 0.3).cos();
    let mut cams = String::new();
    let text = std::fs::read_to_string(dir.join("sparse/0/cameras.txt")).unwrap();
    for l in text.lines().filter(|l| !l.starts_with('#')) {
        let id = l.split_whitespace().next().unwrap();
        cams += &format!("{id} OPENCV 64 48 {fx} {fy} {cx} {cy} -0.3 0.08 0.002 -0.003\n");
    }
    std::fs::write(dir.join("sparse/0/cameras.txt"), cams).unwrap();
    for entry in std::fs::read_dir(dir.join("images")).unwrap() {
        // Distorted pixel centre (u, v) sees the ideal point x with distort(x) = its coordinates:
        // inverted by fixed-point iteration.
        let img = image::RgbImage::from_fn(64, 48, |u, v| {
            let (xd, yd) = ((u as f64 + 0.5 - cx) / fx, (v as f64 + 0.5 - cy) / fy);
            let (mut x, mut y) = (xd, yd);
            for _ in 0..50 {
                let (dx, dy) = d.distort(x, y);
                (x, y) = (x + xd - dx, y + yd - dy);
            }
            let g = pattern(x, y).round() as u8;
            image::Rgb([g, g, g])
        });
        img.save(entry.unwrap().path()).unwrap();
    }
    std::fs::remove_dir_all(dir.join("masks")).unwrap();
    let ds = Dataset::load(&dir, &LoadOptions::default()).unwrap();
    let mut worst = 0f64;
    for f in ds.splits().iter().flat_map(|s| &s.frames) {
        assert!(!f.image.had_alpha);
        for v in 4..44 {
            for u in 4..60 {
                let (x, y) = ((u as f64 + 0.5 - cx) / fx, (v as f64 + 0.5 - cy) / fy);
                let got = f.image.pixel(u, v)[0] as f64;
                worst = worst.max((got - pattern(x, y)).abs());
            }
        }
    }
    assert!(
        worst <= 2.0,
        "undistorted image off the pattern by {worst}/255"
    );
}

/// `Dataset::train_poses` gives the training views' poses exactly as `Dataset::load` does (same
/// views, same order) in every layout, with and without a split file, and reads no pixels:
/// with every image file overwritten by garbage it still answers (IDR excepted: it reads the
/// images' headers for their sizes) while `Dataset::load` fails.
#[test]
fn training_poses_match_the_loaded_ones_without_decoding_images() {
    let src = tempfile::tempdir().unwrap();
    write_dataset(src.path(), 9, 8, 6);
    let loaded = |dir: &std::path::Path| -> Vec<glam::Mat4> {
        let ds = Dataset::load(dir, &LoadOptions::default()).unwrap();
        ds.train.frames.iter().map(|f| f.camera.c2w).collect()
    };
    let spoil = |dir: &std::path::Path| {
        for e in walkdir(dir) {
            if e.extension().is_some_and(|x| x == "png" || x == "jpg") {
                std::fs::write(&e, b"not an image").unwrap();
            }
        }
    };
    let mut dirs: Vec<(String, tempfile::TempDir, std::path::PathBuf, bool)> = Vec::new();
    for target in [Target::ColmapText, Target::ColmapBinary, Target::Idr] {
        let (keep, dir) = converted(src.path(), target);
        dirs.push((format!("{target:?}"), keep, dir, target != Target::Idr));
    }
    let (keep, dir) = converted(src.path(), Target::ColmapBinary);
    std::fs::remove_file(dir.join("split.json")).unwrap();
    dirs.push(("colmap, every 8th held out".into(), keep, dir, true));
    let copy = tempfile::tempdir().unwrap();
    copy_tree(src.path(), copy.path());
    let nerf = copy.path().to_path_buf();
    dirs.push(("nerf-synthetic".into(), copy, nerf, true));
    for (name, _keep, dir, spoilable) in &dirs {
        let want = loaded(dir);
        assert!(!want.is_empty(), "{name}");
        assert_eq!(Dataset::train_poses(dir).unwrap(), want, "{name}");
        if *spoilable {
            spoil(dir);
            assert!(
                Dataset::load(dir, &LoadOptions::default()).is_err(),
                "{name}"
            );
            assert_eq!(
                Dataset::train_poses(dir).unwrap(),
                want,
                "{name}: images spoilt"
            );
        }
    }
    let missing = src.path().join("nowhere");
    let e = format!("{:#}", Dataset::train_poses(&missing).unwrap_err());
    assert!(e.contains("nowhere"), "{e}");
}

fn walkdir(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(walkdir(&p));
        } else {
            out.push(p);
        }
    }
    out
}

fn copy_tree(from: &std::path::Path, to: &std::path::Path) {
    for p in walkdir(from) {
        let dst = to.join(p.strip_prefix(from).unwrap());
        std::fs::create_dir_all(dst.parent().unwrap()).unwrap();
        std::fs::copy(&p, &dst).unwrap();
    }
}
