//! Helpers shared by the data tests: the fixture path and tiny hand-made datasets.
#![allow(dead_code)]

use alphasurf::data::look_at;
use glam::Vec3;
use serde_json::json;
use std::path::{Path, PathBuf};

/// The Blender-rendered fixture; a missing fixture fails the test.
pub fn fixture() -> PathBuf {
    shared_fixture("thin_lyre")
}

/// The fixture `name` in the repository's sibling `shared/fixtures/`; a missing one fails the
/// test.
pub fn shared_fixture(name: &str) -> PathBuf {
    let p = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/fixtures")).join(name);
    assert!(
        p.join("scene.json").is_file(),
        "fixture missing: {} (the repository's sibling shared/fixtures/{name} must exist)",
        p.display()
    );
    p
}

/// A camera-to-world matrix as JSON rows, for a camera at angle `i` on a circle of radius 4.
pub fn c2w_rows(i: usize) -> serde_json::Value {
    let a = i as f32 * 0.7;
    let m = look_at(
        Vec3::new(4.0 * a.cos(), 4.0 * a.sin(), 1.0),
        Vec3::ZERO,
        Vec3::Z,
    );
    let rows: Vec<[f32; 4]> = (0..4).map(|r| m.row(r).to_array()).collect();
    json!(rows)
}

/// A w×h RGBA PNG whose pixels depend on (x, y, seed).
pub fn write_png(path: &Path, w: u32, h: u32, seed: u8) {
    let mut data = Vec::new();
    for y in 0..h {
        for x in 0..w {
            data.extend_from_slice(&[
                (x * 37 + seed as u32) as u8,
                (y * 53) as u8,
                (x * y + 7) as u8,
                ((x + y) * 40 + seed as u32) as u8,
            ]);
        }
    }
    image::save_buffer(path, &data, w, h, image::ColorType::Rgba8).unwrap();
}

/// Writes a valid dataset: `n` frames per split (train, val, test), w×h RGBA PNGs.
pub fn write_dataset(dir: &Path, n: usize, w: u32, h: u32) {
    for split in ["train", "val", "test"] {
        std::fs::create_dir_all(dir.join(split)).unwrap();
        let mut frames = Vec::new();
        for i in 0..n {
            write_png(&dir.join(format!("{split}/r_{i}.png")), w, h, i as u8);
            frames.push(
                json!({"file_path": format!("./{split}/r_{i}"), "transform_matrix": c2w_rows(i)}),
            );
        }
        let doc = json!({"camera_angle_x": 0.6911112, "frames": frames});
        std::fs::write(
            dir.join(format!("transforms_{split}.json")),
            serde_json::to_string_pretty(&doc).unwrap(),
        )
        .unwrap();
    }
}

/// Reads a split's JSON as a value.
pub fn read_json(dir: &Path, split: &str) -> serde_json::Value {
    serde_json::from_str(
        &std::fs::read_to_string(dir.join(format!("transforms_{split}.json"))).unwrap(),
    )
    .unwrap()
}

/// Writes a split's JSON from a value.
pub fn write_json(dir: &Path, split: &str, v: &serde_json::Value) {
    std::fs::write(
        dir.join(format!("transforms_{split}.json")),
        serde_json::to_string_pretty(v).unwrap(),
    )
    .unwrap();
}

/// The NeRF-synthetic → COLMAP/IDR converter of `tools/convert` (its example binary's functions).
#[path = "../../tools/convert/convert.rs"]
pub mod convert;

/// `src` converted to `target` in a new temporary directory (the dataset is its `scene` folder).
pub fn converted(src: &Path, target: convert::Target) -> (tempfile::TempDir, PathBuf) {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("scene");
    convert::convert(src, &out, target).unwrap();
    (d, out)
}

/// Largest entry-wise difference between the camera-to-world matrices of two datasets' views
/// (same splits, same order).
pub fn max_pose_difference(a: &alphasurf::data::Dataset, b: &alphasurf::data::Dataset) -> f32 {
    let mut worst = 0f32;
    for (sa, sb) in a.splits().iter().zip(b.splits()) {
        assert_eq!(sa.name, sb.name);
        assert_eq!(sa.frames.len(), sb.frames.len(), "split {}", sa.name);
        for (fa, fb) in sa.frames.iter().zip(&sb.frames) {
            let d = (fa.camera.c2w - fb.camera.c2w).to_cols_array();
            worst = d.iter().fold(worst, |m, v| m.max(v.abs()));
        }
    }
    worst
}
