//! Bad datasets give a clear error that names the file and the problem (one test each), and a
//! bounded fuzz of the JSON and image parsing never panics.

mod data_common;

use alphasurf::data::{image::decode_bytes, DataError, Dataset, LoadOptions};
use data_common::*;
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
