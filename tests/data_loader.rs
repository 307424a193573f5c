//! The loader on hand-made datasets: nerfstudio intrinsics, RGB PNG and JPEG, file paths with
//! and without extensions, downscaling, and the rays of a whole view.

mod data_common;

use alphasurf::data::{view_rays, Dataset, LoadOptions, SceneBox};
use data_common::*;
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
