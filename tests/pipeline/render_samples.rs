//! `render --pixel-samples`: the rays of an anti-aliased render and how their colours average.

use crate::data_common::write_dataset;
use alphasurf::data::{view_rays, Dataset, LoadOptions};
use alphasurf::train::render_split_with;

/// With n×n samples per pixel the renderer gets n² rays per pixel, pixel by pixel, centred on
/// the pixel's own ray (their mean direction is the centre ray's), all different; each pixel's
/// colour is the mean of its rays' colours clamped to [0, 1]. One sample per pixel is the
/// centre ray itself. Out-of-range counts are errors.
#[test]
fn pixel_samples_are_centred_and_averaged() {
    let dir = tempfile::tempdir().unwrap();
    write_dataset(dir.path(), 2, 7, 5);
    let ds = Dataset::load(dir.path(), &LoadOptions::default()).unwrap();
    let split = &ds.test;
    let centre = view_rays(split, &ds.scene, 0).flat_rays();
    let pixels = centre.len() / 6;
    let fwd = -split.frames[0].camera.c2w.z_axis.truncate();
    for n in [1usize, 2, 3] {
        let per = n * n;
        let mut got: Vec<Vec<f32>> = Vec::new();
        let out = dir.path().join(format!("out{n}"));
        let r = render_split_with(
            &mut |rays| {
                got.push(rays.to_vec());
                // Sample k of a pixel gets 2k/(n²−1) − ½ in every channel: clamped to [0, 1]
                // the samples average to a known value.
                Ok((0..rays.len() / 6)
                    .flat_map(|j| {
                        let k = j % per;
                        let v = if per == 1 {
                            0.25
                        } else {
                            2.0 * k as f32 / (per - 1) as f32 - 0.5
                        };
                        [v; 3]
                    })
                    .collect())
            },
            &ds,
            split,
            &out,
            n as u32,
        )
        .unwrap();
        assert_eq!(r.psnr.len(), split.frames.len());
        // The first view's rays (the calls come view by view; one block per view here).
        let rays = &got[0];
        assert_eq!(rays.len(), 6 * per * pixels, "n = {n}");
        for p in 0..pixels {
            let sub = &rays[6 * per * p..6 * per * (p + 1)];
            // On the image plane (direction / its depth along the viewing axis) a pixel's
            // samples sit symmetrically around its centre.
            let plane = |d: &[f32]| {
                let depth: f64 = (0..3).map(|c| d[c] as f64 * fwd[c] as f64).sum();
                [0, 1, 2].map(|c| d[c] as f64 / depth)
            };
            let mut mean = [0f64; 3];
            for s in sub.chunks(6) {
                assert_eq!(&s[..3], &centre[6 * p..6 * p + 3], "same origin");
                let q = plane(&s[3..6]);
                for c in 0..3 {
                    mean[c] += q[c] / per as f64;
                }
            }
            let want = plane(&centre[6 * p + 3..6 * p + 6]);
            for c in 0..3 {
                assert!((mean[c] - want[c]).abs() < 1e-5, "n = {n}, pixel {p}");
            }
            for (a, b) in sub.chunks(6).zip(sub.chunks(6).skip(1)) {
                assert_ne!(a, b, "n = {n}: two samples of pixel {p} coincide");
            }
        }
        // Clamped mean of 2k/(n²−1) − ½ over k: n = 2: (0 + 1/6 + 5/6 + 1)/4 = 1/2; n = 3:
        // (0 + 0 + 0 + 1/4 + 1/2 + 3/4 + 1 + 1 + 1)/9 = 1/2.
        let want = if n == 1 { 0.25f32 } else { 0.5 };
        let png = image::open(out.join("r_0.png")).unwrap().to_rgb8();
        let byte = (want * 255.0).round() as u8;
        assert!(png.pixels().all(|px| px.0 == [byte; 3]), "n = {n}");
    }
    let e = render_split_with(
        &mut |_| Ok(Vec::new()),
        &ds,
        split,
        &dir.path().join("x"),
        9,
    )
    .unwrap_err();
    assert!(format!("{e:#}").contains("1 to 8"), "{e:#}");
}
