//! The instant-ngp / nerfstudio layout (one `transforms.json`): a NeRF-synthetic scene converted
//! to it with a distorting lens loads back undistorted with the same cameras; lens models and
//! coefficients the loader does not apply are refused by name; no split file holds out every
//! 8th image; EXIF orientation turns photos upright.

use crate::data_common::{convert::Target, converted, max_pose_difference, write_dataset};
use alphasurf::data::distortion::Distortion;
use alphasurf::data::{Dataset, Layout, LoadOptions, SplitRule};
use serde_json::{json, Value};
use std::path::Path;

/// A smooth pattern on the ideal image plane (normalised coordinates), in [0, 255].
fn pattern(x: f64, y: f64, c: usize) -> f64 {
    127.5 + 100.0 * (8.0 * x + c as f64).sin() * (6.0 * y + 0.3).cos()
}

/// A NeRF-synthetic dataset of `n` views per split, w×h, whose images show [`pattern`] through
/// each view's ideal pinhole (opaque).
fn smooth_dataset(dir: &Path, n: usize, w: u32, h: u32) {
    write_dataset(dir, n, w, h);
    let ds = Dataset::load(dir, &LoadOptions::default()).unwrap();
    for f in ds.splits().iter().flat_map(|s| &s.frames) {
        let c = f.camera;
        let img = image::RgbaImage::from_fn(w, h, |u, v| {
            let x = (u as f64 + 0.5 - c.cx as f64) / c.fx as f64;
            let y = (v as f64 + 0.5 - c.cy as f64) / c.fy as f64;
            let p = |ch| pattern(x, y, ch).round() as u8;
            image::Rgba([p(0), p(1), p(2), 255])
        });
        img.save(&f.file).unwrap();
    }
}

fn edit(dir: &Path, f: impl FnOnce(&mut Value)) {
    let path = dir.join("transforms.json");
    let mut v: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    f(&mut v);
    std::fs::write(&path, serde_json::to_string_pretty(&v).unwrap()).unwrap();
}

fn load_err(dir: &Path) -> String {
    format!(
        "{:#}",
        Dataset::load(dir, &LoadOptions::default()).unwrap_err()
    )
}

/// Converted with a strong OPENCV lens (k1, k2, k3, p1, p2 all nonzero), the scene loads as
/// instant-ngp with the original's cameras, split (its `split.json`) and, inside a 4-pixel
/// border, pixels within 3/255 of the original's; left distorted they are far off.
#[test]
fn distorted_transforms_json_loads_undistorted() {
    let src = tempfile::tempdir().unwrap();
    smooth_dataset(src.path(), 2, 64, 48);
    let lens = Distortion::OpenCv {
        k1: -0.45,
        k2: 0.08,
        k3: 0.01,
        p1: 0.002,
        p2: -0.003,
    };
    let (_keep, dir) = converted(src.path(), Target::InstantNgp(lens));
    let orig = Dataset::load(src.path(), &LoadOptions::default()).unwrap();
    let ds = Dataset::load(&dir, &LoadOptions::default()).unwrap();
    assert_eq!(ds.layout, Layout::InstantNgp);
    assert_eq!(ds.split_rule, SplitRule::SplitFile(dir.join("split.json")));
    assert!(max_pose_difference(&orig, &ds) < 1e-6);
    let (mut worst, mut worst_raw) = (0f64, 0f64);
    for (so, sd) in orig.splits().iter().zip(ds.splits()) {
        for (fo, fd) in so.frames.iter().zip(&sd.frames) {
            let (a, b) = (fo.camera, fd.camera);
            assert_eq!((a.fx, a.fy, a.cx, a.cy), (b.fx, b.fy, b.cx, b.cy));
            let raw = image::open(&fd.file).unwrap().to_rgba8();
            for v in 4..44 {
                for u in 4..60 {
                    for c in 0..3 {
                        let want = fo.image.pixel(u, v)[c] as f64;
                        worst = worst.max((fd.image.pixel(u, v)[c] as f64 - want).abs());
                        worst_raw = worst_raw.max((raw.get_pixel(u, v)[c] as f64 - want).abs());
                    }
                }
            }
        }
    }
    assert!(worst <= 3.0, "undistorted images off by {worst}/255");
    assert!(
        worst_raw >= 12.0,
        "the lens barely changed the images ({worst_raw}/255)"
    );
}

/// Without a split file every 8th image by name is held out; `--downscale 2` reads `images_2/`.
#[test]
fn transforms_json_without_split_holds_out_every_eighth_image() {
    let src = tempfile::tempdir().unwrap();
    write_dataset(src.path(), 6, 8, 6);
    let (_keep, dir) = converted(src.path(), Target::InstantNgp(Distortion::None));
    std::fs::remove_file(dir.join("split.json")).unwrap();
    let ds = Dataset::load(&dir, &LoadOptions::default()).unwrap();
    assert_eq!(ds.split_rule, SplitRule::EveryNth(8));
    assert_eq!((ds.train.frames.len(), ds.test.frames.len()), (15, 3));
    assert!(ds.val_split.is_none());
    assert!(ds.foreground.is_some(), "a box found from the cameras");
    // Half-size copies in images_2/ and masks_2/ are what --downscale 2 reads.
    for (full, half) in [("images", "images_2"), ("masks", "masks_2")] {
        std::fs::create_dir_all(dir.join(half)).unwrap();
        for e in std::fs::read_dir(dir.join(full)).unwrap() {
            let p = e.unwrap().path();
            let small =
                image::open(&p)
                    .unwrap()
                    .resize_exact(4, 3, image::imageops::FilterType::Nearest);
            small
                .save(dir.join(half).join(p.file_name().unwrap()))
                .unwrap();
        }
    }
    let opts = LoadOptions {
        downscale: 2,
        ..Default::default()
    };
    let ds2 = Dataset::load(&dir, &opts).unwrap();
    let f = &ds2.train.frames[0];
    assert!(
        f.file.starts_with(dir.join("images_2")),
        "{}",
        f.file.display()
    );
    assert_eq!((f.image.width, f.image.height), (4, 3));
    assert_eq!(f.camera.fx * 2.0, ds.train.frames[0].camera.fx);
}

/// Lens models and coefficients the loader does not apply are errors naming them; zero
/// coefficients on a PINHOLE camera load.
#[test]
fn unapplied_lenses_are_refused_by_name() {
    let src = tempfile::tempdir().unwrap();
    write_dataset(src.path(), 1, 8, 6);
    let (_keep, dir) = converted(src.path(), Target::InstantNgp(Distortion::None));
    let cases: [(&str, Value, &str); 5] = [
        ("camera_model", json!("OPENCV_FISHEYE"), "OPENCV_FISHEYE"),
        ("camera_model", json!("EQUIRECTANGULAR"), "EQUIRECTANGULAR"),
        ("is_fisheye", json!(true), "is_fisheye"),
        ("k4", json!(0.01), "k4 = 0.01"),
        ("s1", json!(-0.2), "s1 = -0.2"),
    ];
    for (key, value, named) in cases {
        let d = tempfile::tempdir().unwrap();
        let case = d.path().join("c");
        copy_dir(&dir, &case);
        edit(&case, |v| v[key] = value.clone());
        let err = load_err(&case);
        assert!(
            err.contains(named) && err.contains("transforms.json"),
            "{key}: {err}"
        );
    }
    // A PINHOLE camera with a nonzero coefficient: refused; with zeros: loads.
    edit(&dir, |v| {
        v["camera_model"] = json!("PINHOLE");
        v["frames"][1]["k1"] = json!(0.05);
    });
    let err = load_err(&dir);
    assert!(err.contains("PINHOLE") && err.contains("k1 = 0.05") && err.contains("frame 1"));
    edit(&dir, |v| v["frames"][1]["k1"] = json!(0.0));
    Dataset::load(&dir, &LoadOptions::default()).unwrap();
    // The NeRF-synthetic layout applies the same rules.
    let mut t: Value = serde_json::from_str(
        &std::fs::read_to_string(src.path().join("transforms_train.json")).unwrap(),
    )
    .unwrap();
    t["k5"] = json!(0.3);
    std::fs::write(
        src.path().join("transforms_train.json"),
        serde_json::to_string(&t).unwrap(),
    )
    .unwrap();
    let err = load_err(src.path());
    assert!(
        err.contains("k5 = 0.3") && err.contains("transforms_train.json"),
        "{err}"
    );
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &to.join(e.file_name()));
        } else {
            std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
        }
    }
}

/// A JPEG whose EXIF orientation is 6 (rotate 90° clockwise to view) decodes upright: a 16×8
/// image red on the left and blue on the right is 8×16, red on top.
#[test]
fn exif_orientation_turns_photos_upright() {
    let img = image::RgbImage::from_fn(16, 8, |x, _| {
        if x < 8 {
            image::Rgb([255, 0, 0])
        } else {
            image::Rgb([0, 0, 255])
        }
    });
    let mut jpeg = Vec::new();
    img.write_to(
        &mut std::io::Cursor::new(&mut jpeg),
        image::ImageFormat::Jpeg,
    )
    .unwrap();
    // APP1 "Exif": a little-endian TIFF header and one IFD entry, Orientation (0x0112) = 6.
    let mut tiff = b"II*\0\x08\0\0\0".to_vec();
    tiff.extend([1, 0, 0x12, 0x01, 3, 0, 1, 0, 0, 0, 6, 0, 0, 0, 0, 0, 0, 0]);
    let mut app1 = b"Exif\0\0".to_vec();
    app1.extend(tiff);
    let mut bytes = jpeg[..2].to_vec();
    bytes.extend([0xFF, 0xE1]);
    bytes.extend(((app1.len() + 2) as u16).to_be_bytes());
    bytes.extend(app1);
    bytes.extend(&jpeg[2..]);
    let d = tempfile::tempdir().unwrap();
    let path = d.path().join("photo.jpg");
    std::fs::write(&path, &bytes).unwrap();
    let (w, h, data, _) = alphasurf::data::image::decode_file(&path).unwrap();
    assert_eq!((w, h), (8, 16));
    assert_eq!(alphasurf::data::image::image_size(&path).unwrap(), (8, 16));
    let px = |x: u32, y: u32| &data[4 * (y * w + x) as usize..][..3];
    assert!(px(4, 2)[0] > 200 && px(4, 2)[2] < 60, "top {:?}", px(4, 2));
    assert!(
        px(4, 13)[2] > 200 && px(4, 13)[0] < 60,
        "bottom {:?}",
        px(4, 13)
    );
}

/// instant-ngp's `aabb_scale` bounds the box found from the cameras (±0.5·a/0.33 around the
/// origin by default); nerfstudio's `applied_transform` is checked and a malformed one is an
/// error naming it.
#[test]
fn aabb_scale_bounds_the_box_and_applied_transform_is_checked() {
    let src = tempfile::tempdir().unwrap();
    write_dataset(src.path(), 2, 8, 6);
    let (_keep, dir) = converted(src.path(), Target::InstantNgp(Distortion::None));
    let before = Dataset::load(&dir, &LoadOptions::default()).unwrap();
    let b = before.foreground.unwrap().bounds;
    assert!(b.hi().max_element() > 1.0, "{b}");
    edit(&dir, |v| {
        v["aabb_scale"] = json!(0.5);
        v["applied_transform"] = json!([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]]);
    });
    let ds = Dataset::load(&dir, &LoadOptions::default()).unwrap();
    let fg = ds.foreground.unwrap();
    let half = 0.5 * 0.5 / 0.33;
    assert!(
        fg.bounds.lo().cmpge(glam::Vec3::splat(-half - 1e-5)).all()
            && fg.bounds.hi().cmple(glam::Vec3::splat(half + 1e-5)).all(),
        "{}",
        fg.bounds
    );
    assert!(fg.how.contains("aabb_scale"), "{}", fg.how);
    edit(&dir, |v| {
        v["applied_transform"] = json!([[1, 0, 0], [0, 1, 0]])
    });
    let err = load_err(&dir);
    assert!(
        err.contains("applied_transform") && err.contains("row lengths"),
        "{err}"
    );
}

/// nerfstudio's `ply_file_path` gives the sparse points the box is found from: a dense cluster
/// at the origin on a wide floor is boxed tightly (the floor's plane set aside); a path outside
/// the dataset is refused naming the key.
#[test]
fn ply_file_path_points_bound_the_foreground_box() {
    let src = tempfile::tempdir().unwrap();
    write_dataset(src.path(), 3, 8, 6);
    let (_keep, dir) = converted(src.path(), Target::InstantNgp(Distortion::None));
    let mut pts: Vec<[f32; 3]> = (0..1500)
        .map(|i| {
            let (a, b) = (i as f32 * 0.37, i as f32 * 0.011);
            [
                0.3 * a.cos() * b.sin(),
                0.3 * a.sin() * b.sin(),
                0.3 * b.cos(),
            ]
        })
        .collect();
    pts.extend((0..3600).map(|i| {
        [
            (i % 60) as f32 * 0.1 - 3.0,
            (i / 60) as f32 * 0.1 - 3.0,
            -0.5,
        ]
    }));
    alphasurf::io::write_points(&dir.join("sparse_pc.ply"), &pts).unwrap();
    edit(&dir, |v| v["ply_file_path"] = json!("sparse_pc.ply"));
    let ds = Dataset::load(&dir, &LoadOptions::default()).unwrap();
    let fg = ds.foreground.unwrap();
    let (lo, hi) = (fg.bounds.lo(), fg.bounds.hi());
    assert!(
        lo.cmple(glam::Vec3::splat(-0.29)).all()
            && hi.cmpge(glam::Vec3::splat(0.29)).all()
            && lo.cmpge(glam::Vec3::splat(-0.45)).all()
            && hi.cmple(glam::Vec3::splat(0.45)).all(),
        "{} ({})",
        fg.bounds,
        fg.how
    );
    assert!(fg.how.contains("1 planes"), "{}", fg.how);
    edit(&dir, |v| v["ply_file_path"] = json!("../outside.ply"));
    let err = load_err(&dir);
    assert!(
        err.contains("ply_file_path") && err.contains("inside the dataset"),
        "{err}"
    );
}
