//! Bad datasets (NeRF-synthetic, COLMAP, IDR) give a clear error that names the file and the
//! problem (one test each), and a bounded fuzz of the JSON, image, COLMAP binary and npz parsing
//! never panics.

use crate::data_common::convert::Target;
use crate::data_common::*;
use alphasurf::data::{image::decode_bytes, DataError, Dataset, LoadOptions};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use serde_json::json;
use std::path::Path;

fn load_err(dir: &Path) -> (String, anyhow::Error) {
    let e = Dataset::load(dir, &LoadOptions::default()).expect_err("loading should fail");
    (format!("{e:#}"), e)
}

fn valid() -> tempfile::TempDir {
    let d = tempfile::tempdir().unwrap();
    write_dataset(d.path(), 2, 8, 6);
    d
}

#[test]
fn valid_dataset_loads() {
    let d = valid();
    let ds = Dataset::load(d.path(), &LoadOptions::default()).unwrap();
    assert_eq!(ds.train.frames.len(), 2);
    assert_eq!((ds.train.width(), ds.train.height()), (8, 6));
}

#[test]
fn missing_directory() {
    let d = tempfile::tempdir().unwrap();
    let gone = d.path().join("nope");
    let (msg, e) = load_err(&gone);
    assert!(
        matches!(
            e.downcast_ref::<DataError>(),
            Some(DataError::MissingDir { .. })
        ),
        "{msg}"
    );
    assert!(
        msg.contains("nope") && msg.contains("does not exist"),
        "{msg}"
    );
}

#[test]
fn missing_split() {
    let d = valid();
    std::fs::remove_file(d.path().join("transforms_train.json")).unwrap();
    let (msg, e) = load_err(d.path());
    assert!(
        matches!(
            e.downcast_ref::<DataError>(),
            Some(DataError::MissingSplit { .. })
        ),
        "{msg}"
    );
    assert!(
        msg.contains("transforms_train.json") && msg.contains("not found"),
        "{msg}"
    );
}

#[test]
fn val_falls_back_to_test() {
    let d = valid();
    std::fs::remove_file(d.path().join("transforms_val.json")).unwrap();
    let ds = Dataset::load(d.path(), &LoadOptions::default()).unwrap();
    assert!(ds.val_split.is_none());
    assert_eq!(ds.val().name, "test");
}

#[test]
fn malformed_json_reports_line_and_column() {
    let d = valid();
    std::fs::write(
        d.path().join("transforms_test.json"),
        "{\n  \"camera_angle_x\": 0.69,\n  \"frames\": [ oops ]\n}",
    )
    .unwrap();
    let (msg, e) = load_err(d.path());
    match e.downcast_ref::<DataError>() {
        Some(DataError::Json { line, column, .. }) => {
            assert_eq!((*line, *column), (3, 15), "{msg}")
        }
        other => panic!("expected a JSON error, got {other:?}: {msg}"),
    }
    assert!(
        msg.contains("transforms_test.json") && msg.contains("line 3, column 15"),
        "{msg}"
    );
}

#[test]
fn missing_image() {
    let d = valid();
    std::fs::remove_file(d.path().join("val/r_1.png")).unwrap();
    let (msg, e) = load_err(d.path());
    assert!(
        matches!(
            e.downcast_ref::<DataError>(),
            Some(DataError::MissingImage { .. })
        ),
        "{msg}"
    );
    assert!(
        msg.contains("val/r_1.png") && msg.contains("not found"),
        "{msg}"
    );
}

#[test]
fn unreadable_image() {
    let d = valid();
    std::fs::write(
        d.path().join("train/r_1.png"),
        b"\x89PNG\r\n\x1a\nthis is not a png",
    )
    .unwrap();
    let (msg, e) = load_err(d.path());
    assert!(
        matches!(
            e.downcast_ref::<DataError>(),
            Some(DataError::UnreadableImage { .. })
        ),
        "{msg}"
    );
    assert!(
        msg.contains("train/r_1.png") && msg.contains("cannot read image"),
        "{msg}"
    );
}

#[test]
fn mixed_image_sizes() {
    let d = valid();
    write_png(&d.path().join("train/r_1.png"), 9, 6, 0);
    let (msg, e) = load_err(d.path());
    assert!(
        matches!(
            e.downcast_ref::<DataError>(),
            Some(DataError::MixedSizes { .. })
        ),
        "{msg}"
    );
    assert!(
        msg.contains("train/r_1.png") && msg.contains("9x6") && msg.contains("8x6"),
        "{msg}"
    );
    // Across splits too.
    let d = valid();
    write_png(&d.path().join("test/r_0.png"), 4, 4, 0);
    write_png(&d.path().join("test/r_1.png"), 4, 4, 0);
    let (msg, _) = load_err(d.path());
    assert!(msg.contains("test/r_0.png") && msg.contains("4x4"), "{msg}");
}

#[test]
fn declared_size_must_match_image() {
    let d = valid();
    let mut v = read_json(d.path(), "train");
    v["w"] = json!(16);
    v["h"] = json!(6);
    write_json(d.path(), "train", &v);
    let (msg, e) = load_err(d.path());
    assert!(
        matches!(
            e.downcast_ref::<DataError>(),
            Some(DataError::MixedSizes { .. })
        ),
        "{msg}"
    );
    assert!(msg.contains("'w' = 16"), "{msg}");
}

#[test]
fn non_finite_transform() {
    let d = valid();
    let mut v = read_json(d.path(), "train");
    v["frames"][1]["transform_matrix"][0][3] = json!(1e39); // finite in JSON, infinite as f32
    write_json(d.path(), "train", &v);
    let (msg, e) = load_err(d.path());
    assert!(
        matches!(
            e.downcast_ref::<DataError>(),
            Some(DataError::BadTransform { frame: 1, .. })
        ),
        "{msg}"
    );
    assert!(
        msg.contains("transforms_train.json") && msg.contains("non-finite"),
        "{msg}"
    );
}

#[test]
fn singular_transform() {
    let d = valid();
    let mut v = read_json(d.path(), "test");
    v["frames"][0]["transform_matrix"] =
        json!([[1, 0, 0, 0], [2, 0, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]]);
    write_json(d.path(), "test", &v);
    let (msg, e) = load_err(d.path());
    assert!(
        matches!(
            e.downcast_ref::<DataError>(),
            Some(DataError::BadTransform { frame: 0, .. })
        ),
        "{msg}"
    );
    assert!(
        msg.contains("transforms_test.json") && msg.contains("singular"),
        "{msg}"
    );
}

#[test]
fn malformed_transform_shape() {
    let d = valid();
    let mut v = read_json(d.path(), "test");
    v["frames"][0]["transform_matrix"] = json!([[1, 0, 0], [0, 1, 0]]);
    write_json(d.path(), "test", &v);
    let (msg, _) = load_err(d.path());
    assert!(
        msg.contains("transforms_test.json") && msg.contains("4x4"),
        "{msg}"
    );
}

#[test]
fn empty_split() {
    let d = valid();
    write_json(
        d.path(),
        "val",
        &json!({"camera_angle_x": 0.69, "frames": []}),
    );
    let (msg, e) = load_err(d.path());
    assert!(
        matches!(
            e.downcast_ref::<DataError>(),
            Some(DataError::EmptySplit { .. })
        ),
        "{msg}"
    );
    assert!(
        msg.contains("transforms_val.json") && msg.contains("no frames"),
        "{msg}"
    );
}

#[test]
fn file_path_outside_dataset() {
    let d = valid();
    // A real image outside the dataset directory, reachable by "..".
    let outside = tempfile::tempdir().unwrap();
    write_png(&outside.path().join("x.png"), 8, 6, 0);
    let rel = format!(
        "../{}/x.png",
        outside.path().file_name().unwrap().to_str().unwrap()
    );
    for bad in [rel.as_str(), "./train/../../r_0", "/etc/passwd"] {
        let mut v = read_json(d.path(), "train");
        v["frames"][0]["file_path"] = json!(bad);
        write_json(d.path(), "train", &v);
        let (msg, e) = load_err(d.path());
        assert!(
            matches!(
                e.downcast_ref::<DataError>(),
                Some(DataError::PathEscape { .. })
            ),
            "{bad}: {msg}"
        );
        assert!(
            msg.contains("transforms_train.json") && msg.contains("outside the dataset"),
            "{msg}"
        );
    }
    // ".." that stays inside is fine.
    let mut v = read_json(d.path(), "train");
    v["frames"][0]["file_path"] = json!("./val/../train/r_0");
    write_json(d.path(), "train", &v);
    Dataset::load(d.path(), &LoadOptions::default()).unwrap();
}

#[test]
fn missing_intrinsics() {
    let d = valid();
    let mut v = read_json(d.path(), "train");
    v.as_object_mut().unwrap().remove("camera_angle_x");
    write_json(d.path(), "train", &v);
    let (msg, _) = load_err(d.path());
    assert!(
        msg.contains("transforms_train.json") && msg.contains("camera_angle_x"),
        "{msg}"
    );
}

#[test]
fn bad_downscale() {
    let d = valid();
    for k in [0, 7] {
        let e = Dataset::load(
            d.path(),
            &LoadOptions {
                downscale: k,
                ..Default::default()
            },
        )
        .unwrap_err();
        let msg = format!("{e:#}");
        assert!(msg.contains("--downscale"), "{msg}");
    }
}

/// Random byte-level mutations: flip, insert, delete, truncate, duplicate a span.
fn mutate(rng: &mut Pcg64, src: &[u8]) -> Vec<u8> {
    let mut v = src.to_vec();
    for _ in 0..rng.random_range(1..4) {
        if v.is_empty() {
            break;
        }
        let i = rng.random_range(0..v.len());
        match rng.random_range(0..5) {
            0 => v[i] ^= 1 << rng.random_range(0..8),
            1 => v.insert(i, b"{}[],:\"0-e.9 nul"[rng.random_range(0..16)]),
            2 => {
                v.remove(i);
            }
            3 => v.truncate(i),
            _ => {
                let j = (i + rng.random_range(1..16)).min(v.len());
                let span = v[i..j].to_vec();
                v.splice(i..i, span);
            }
        }
    }
    v
}

#[test]
fn fuzz_json_never_panics() {
    let d = valid();
    let src = std::fs::read(d.path().join("transforms_train.json")).unwrap();
    let mut rng = Pcg64::seed_from_u64(7);
    let (mut ok, mut err) = (0, 0);
    for _ in 0..300 {
        std::fs::write(
            d.path().join("transforms_train.json"),
            mutate(&mut rng, &src),
        )
        .unwrap();
        match Dataset::load(d.path(), &LoadOptions::default()) {
            Ok(_) => ok += 1,
            Err(e) => {
                let msg = format!("{e:#}");
                assert!(
                    msg.contains(&d.path().display().to_string()),
                    "error does not name the dataset: {msg}"
                );
                err += 1;
            }
        }
    }
    assert_eq!(ok + err, 300);
    assert!(
        err > 100,
        "mutations should mostly break the JSON ({err} errors)"
    );
}

#[test]
fn fuzz_images_never_panic() {
    let d = valid();
    let png = std::fs::read(d.path().join("train/r_0.png")).unwrap();
    let mut jpeg = Vec::new();
    image::DynamicImage::ImageRgb8(image::RgbImage::from_fn(8, 6, |x, y| {
        image::Rgb([x as u8 * 30, y as u8 * 40, 99])
    }))
    .write_to(
        &mut std::io::Cursor::new(&mut jpeg),
        image::ImageFormat::Jpeg,
    )
    .unwrap();
    let mut rng = Pcg64::seed_from_u64(11);
    for i in 0..400 {
        let src = if i % 2 == 0 { &png } else { &jpeg };
        let bytes = mutate(&mut rng, src);
        if let Ok((w, h, data, _)) = decode_bytes(&bytes) {
            assert_eq!(data.len(), (w * h * 4) as usize);
        }
        if i % 20 == 0 {
            // Through the whole loader as well.
            std::fs::write(d.path().join("train/r_1.png"), &bytes).unwrap();
            let _ = Dataset::load(d.path(), &LoadOptions::default());
        }
    }
}

/// A tiny NeRF-synthetic dataset converted to `target`.
fn small(target: Target) -> (tempfile::TempDir, std::path::PathBuf) {
    let src = valid();
    converted(src.path(), target)
}

/// Asserts the load fails with `want` in the message, naming `file`.
fn fails_naming(dir: &Path, file: &str, want: &str) -> anyhow::Error {
    let (msg, e) = load_err(dir);
    assert!(msg.contains(file) && msg.contains(want), "{msg}");
    assert!(e.downcast_ref::<DataError>().is_some(), "{msg}");
    e
}

fn edit(path: &Path, f: impl FnOnce(String) -> String) {
    std::fs::write(path, f(std::fs::read_to_string(path).unwrap())).unwrap();
}

#[test]
fn unknown_layout() {
    let d = tempfile::tempdir().unwrap();
    let e = fails_naming(d.path(), &d.path().display().to_string(), "not a dataset");
    assert!(matches!(
        e.downcast_ref(),
        Some(DataError::UnknownLayout { .. })
    ));
}

#[test]
fn colmap_unknown_and_unsupported_camera_models() {
    let (_k, dir) = small(Target::ColmapText);
    let cams = dir.join("sparse/0/cameras.txt");
    edit(&cams, |s| s.replacen("PINHOLE", "PINHOLE_42", 1));
    let e = fails_naming(
        &dir,
        "cameras.txt",
        "camera model PINHOLE_42 is not supported",
    );
    assert!(matches!(
        e.downcast_ref(),
        Some(DataError::CameraModel { .. })
    ));
    edit(&cams, |s| s.replacen("PINHOLE_42", "OPENCV_FISHEYE", 1));
    let (msg, _) = load_err(&dir);
    assert!(
        msg.contains("OPENCV_FISHEYE") && msg.contains("undistort"),
        "{msg}"
    );
    // Binary: an unknown model id cannot even be skipped (its parameter count is unknown).
    let (_k, dir) = small(Target::ColmapBinary);
    let cams = dir.join("sparse/0/cameras.bin");
    let mut b = std::fs::read(&cams).unwrap();
    b[12..16].copy_from_slice(&42i32.to_le_bytes());
    std::fs::write(&cams, b).unwrap();
    fails_naming(&dir, "cameras.bin", "camera model id 42 is not supported");
}

#[test]
fn colmap_binary_truncated_or_with_trailing_bytes() {
    let (_k, dir) = small(Target::ColmapBinary);
    let images = dir.join("sparse/0/images.bin");
    let full = std::fs::read(&images).unwrap();
    // Declares 6 images but holds 5 and a half.
    std::fs::write(&images, &full[..full.len() - 30]).unwrap();
    let e = fails_naming(
        &dir,
        "images.bin",
        "truncated: the file ends in image 6 of the 6",
    );
    assert!(matches!(
        e.downcast_ref(),
        Some(DataError::Truncated { .. })
    ));
    // Declares 5 of the 6 entries present.
    let mut b = full.clone();
    b[..8].copy_from_slice(&5u64.to_le_bytes());
    std::fs::write(&images, b).unwrap();
    let e = fails_naming(
        &dir,
        "images.bin",
        "bytes follow the 5 images the file declares",
    );
    assert!(matches!(
        e.downcast_ref(),
        Some(DataError::CountMismatch { .. })
    ));
}

#[test]
fn colmap_missing_image_mask_and_camera() {
    let (_k, dir) = small(Target::ColmapText);
    std::fs::remove_file(dir.join("images/test_r_1.png")).unwrap();
    let e = fails_naming(
        &dir,
        "images/test_r_1.png",
        "not found (image 'test_r_1.png' posed in",
    );
    assert!(matches!(
        e.downcast_ref(),
        Some(DataError::MissingViewFile { .. })
    ));
    // Issue 44: a posed image that is there but unreadable (a symbolic link loop, a folder) is
    // said to be unreadable, not missing.
    let (_k, dir) = small(Target::ColmapText);
    let img = dir.join("images/test_r_1.png");
    std::fs::remove_file(&img).unwrap();
    std::os::unix::fs::symlink("test_r_1.png", &img).unwrap();
    fails_naming(&dir, "images/test_r_1.png", "cannot read image");
    std::fs::remove_file(&img).unwrap();
    std::fs::create_dir(&img).unwrap();
    fails_naming(&dir, "images/test_r_1.png", "a folder, not an image");
    let (_k, dir) = small(Target::ColmapText);
    std::fs::remove_file(dir.join("masks/val_r_0.png")).unwrap();
    fails_naming(&dir, "masks/val_r_0.png", "not found");
    let (_k, dir) = small(Target::ColmapText);
    edit(&dir.join("sparse/0/cameras.txt"), |s| {
        s.replacen("\n3 PINHOLE", "\n33 PINHOLE", 1)
    });
    fails_naming(&dir, "images.txt", "uses camera 3, which");
}

/// Issue 44: a camera line with too few parameters says so (not "model not supported"), and a
/// distortion no lens has is refused at load instead of failing training later.
#[test]
fn colmap_parameter_count_and_impossible_distortion() {
    let (_k, dir) = small(Target::ColmapText);
    let cams = dir.join("sparse/0/cameras.txt");
    let orig = std::fs::read_to_string(&cams).unwrap();
    let line = orig.lines().find(|l| l.contains(" PINHOLE ")).unwrap();
    let f: Vec<&str> = line.split_whitespace().collect();
    let short = format!("{} PINHOLE {} {} 44", f[0], f[2], f[3]);
    std::fs::write(&cams, orig.replacen(line, &short, 1)).unwrap();
    let (msg, _) = load_err(&dir);
    assert!(
        msg.contains("cameras.txt")
            && msg.contains("takes 4 parameters")
            && msg.contains("has 1")
            && !msg.contains("not supported"),
        "{msg}"
    );
    // SIMPLE_RADIAL f cx cy k1 with k1 = 1e6.
    let radial = format!(
        "{} SIMPLE_RADIAL {} {} {} {} {} 1e6",
        f[0], f[2], f[3], f[4], f[6], f[7]
    );
    std::fs::write(&cams, orig.replacen(line, &radial, 1)).unwrap();
    let (msg, _) = load_err(&dir);
    assert!(
        msg.contains("distortion k1 1000000") && msg.contains("not a lens"),
        "{msg}"
    );
    let mild = format!(
        "{} SIMPLE_RADIAL {} {} {} {} {} 0.01",
        f[0], f[2], f[3], f[4], f[6], f[7]
    );
    std::fs::write(&cams, orig.replacen(line, &mild, 1)).unwrap();
    Dataset::load(&dir, &LoadOptions::default()).unwrap();
}

#[test]
fn colmap_nan_pose_and_bad_numbers() {
    let (_k, dir) = small(Target::ColmapText);
    let images = dir.join("sparse/0/images.txt");
    let orig = std::fs::read_to_string(&images).unwrap();
    let line = orig.lines().find(|l| l.starts_with("2 ")).unwrap();
    let mut f: Vec<&str> = line.split(' ').collect();
    f[5] = "NaN";
    edit(&images, |s| s.replace(line, &f.join(" ")));
    let e = fails_naming(&dir, "images.txt", "non-finite pose");
    assert!(matches!(e.downcast_ref(), Some(DataError::BadPose { .. })));
    f[5] = "zero";
    std::fs::write(&images, orig.replace(line, &f.join(" "))).unwrap();
    fails_naming(&dir, "images.txt", "TX 'zero' is not a number");
}

#[test]
fn idr_mismatched_counts_and_nan_matrix() {
    let (_k, dir) = small(Target::Idr);
    std::fs::remove_file(dir.join("image/000005.png")).unwrap();
    let e = fails_naming(&dir, "image", "5 images but cameras_sphere.npz poses 6");
    assert!(matches!(
        e.downcast_ref(),
        Some(DataError::CountMismatch { .. })
    ));
    let (_k, dir) = small(Target::Idr);
    std::fs::remove_file(dir.join("mask/002.png")).unwrap();
    fails_naming(&dir, "mask", "5 images but cameras_sphere.npz poses 6");
    let (_k, dir) = small(Target::Idr);
    let npz = dir.join("cameras_sphere.npz");
    alphasurf::grid::npz::write_atomic(&npz, |z| {
        for i in 0..6 {
            let mut w = [0f64; 16];
            (w[0], w[5], w[10], w[15], w[3]) = (50.0, 50.0, 1.0, 1.0, 4.0);
            if i == 4 {
                w[7] = f64::NAN;
            }
            z.array(&format!("world_mat_{i}"), &[4, 4], &w)?;
            let s = [
                1.5, 0., 0., 0., 0., 1.5, 0., 0., 0., 0., 1.5, 0., 0., 0., 0., 1.,
            ];
            z.array(&format!("scale_mat_{i}"), &[4, 4], &s)?;
        }
        Ok(())
    })
    .unwrap();
    let e = fails_naming(
        &dir,
        "cameras_sphere.npz",
        "image '000004.png': world_mat_4: non-finite",
    );
    assert!(matches!(e.downcast_ref(), Some(DataError::BadPose { .. })));
}

/// Random byte edits of the binary model and the npz give errors, never a panic.
#[test]
fn fuzz_colmap_binary_and_idr_never_panic() {
    let mut rng = Pcg64::seed_from_u64(23);
    for (target, file) in [
        (Target::ColmapBinary, "sparse/0/cameras.bin"),
        (Target::ColmapBinary, "sparse/0/images.bin"),
        (Target::ColmapBinary, "sparse/0/points3D.bin"),
        (Target::Idr, "cameras_sphere.npz"),
    ] {
        let (_k, dir) = small(target);
        let path = dir.join(file);
        let orig = std::fs::read(&path).unwrap();
        for _ in 0..40 {
            std::fs::write(&path, mutate(&mut rng, &orig)).unwrap();
            let _ = Dataset::load(&dir, &LoadOptions::default());
        }
    }
}
