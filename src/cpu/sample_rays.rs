//! Twin of `glsl/sample_rays.comp`: a batch of training rays drawn from a split's pixels by a
//! counter-based hash of (seed, ray index) — uniformly, or with a share of the batch from the
//! pixels the object covers ([`Focus`]) — ordered by (view, Z-order) in runs of
//! [`SAMPLE_SORT_RAYS`], with their rays and target colours.

use crate::abi::consts::SAMPLE_SORT_RAYS;
use crate::abi::rays::{key_pixel, sorted_keys, SampleSet, SampledRays};
use crate::math::ndc::ndc_ray;
use anyhow::Result;
use rayon::prelude::*;

/// Ray (origin, unit direction) and target colour of the pixel `key` names, as the kernel
/// computes them (the formula of `data::Camera::pixel_ray`, in its order of operations; then
/// into NDC for a set that has the map).
fn ray_of(set: &SampleSet, key: u64) -> ([f32; 6], [f32; 3]) {
    let (view, x, y) = key_pixel(key, set.key_bits());
    let c = &set.cams[view as usize];
    let dx = (x as f32 + 0.5 - c.centre[0]) / c.focal[0];
    let dy = -((y as f32 + 0.5 - c.centre[1]) / c.focal[1]);
    let d: [f32; 3] = std::array::from_fn(|k| c.x_axis[k] * dx + c.y_axis[k] * dy + -c.z_axis[k]);
    let len2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    let inv = 1.0 / len2.sqrt();
    let o = c.origin;
    let d = [d[0] * inv, d[1] * inv, d[2] * inv];
    let ray = match set.ndc {
        Some(p) => ndc_ray(o, d, p),
        None => [o[0], o[1], o[2], d[0], d[1], d[2]],
    };
    let at = 4 * (y as usize * set.width as usize + x as usize);
    let px = &set.images[view as usize][at..at + 3];
    (ray, std::array::from_fn(|k| px[k] as f32 / 255.0))
}

/// Draws `n` rays with `seed`: ray i picks pixel splitmix64(seed, i) mod n_pixels (uniform over
/// every pixel of the set, with replacement; the bias of the modulo is below n_pixels / 2^64),
/// or a focus pixel for the share of the rays [`Focus`] says (then with importance weights);
/// each run of [`SAMPLE_SORT_RAYS`] rays is sorted by key (the key determines the pixel, so the
/// sorted run is unique and any sort gives the kernel's bitonic order, `cpu::sample_rays_sort`).
pub fn sample_rays(set: &SampleSet, seed: u64, n: usize) -> Result<SampledRays> {
    let keys = sorted_keys(set, seed, n)?;
    let (rays, targets): (Vec<[f32; 6]>, Vec<[f32; 3]>) = keys
        .par_iter()
        .with_min_len(SAMPLE_SORT_RAYS as usize)
        .map(|&k| ray_of(set, k))
        .unzip();
    let weights = if set.focus.is_none() {
        Vec::new()
    } else {
        let (per_view, bits) = (set.width as u64 * set.height as u64, set.key_bits());
        let (w_focus, w_other) = set.focus.weights();
        keys.par_iter()
            .map(|&k| {
                let (v, x, y) = key_pixel(k, bits);
                let p = v as u64 * per_view + (y * set.width + x) as u64;
                if set.focus.contains(p) {
                    w_focus
                } else {
                    w_other
                }
            })
            .collect()
    };
    Ok(SampledRays {
        keys,
        rays: rays.into_flattened(),
        targets: targets.into_flattened(),
        weights,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::abi::buffers::SampleCamera;
    use crate::abi::rays::{pixel_key, Focus};

    fn set(images: &[Vec<u8>], w: u32, h: u32) -> SampleSet<'_> {
        let cam = SampleCamera {
            x_axis: [1.0, 0.0, 0.0],
            y_axis: [0.0, 1.0, 0.0],
            z_axis: [0.0, 0.0, 1.0],
            origin: [0.0, 0.0, 2.0],
            focal: [w as f32, h as f32],
            centre: [0.5 * w as f32, 0.5 * h as f32],
        };
        SampleSet {
            width: w,
            height: h,
            images: images.iter().map(|i| i.as_slice()).collect(),
            cams: vec![cam; images.len()],
            focus: Focus::none(),
            ndc: None,
        }
    }

    #[test]
    fn keys_round_trip_and_order_as_view_then_z_order() {
        for bits in [0, 1, 5, 10, 16] {
            let m = (1u32 << bits) - 1;
            for (v, x, y) in [
                (0, 0, 0),
                (3, m, 0),
                (7, 0, m),
                (1 << 20, m, m),
                (2, m / 3, m / 2),
            ] {
                assert_eq!(key_pixel(pixel_key(v, x, y, bits), bits), (v, x, y));
            }
        }
        assert_eq!(pixel_key(0, 1, 0, 4), 1);
        assert_eq!(pixel_key(0, 0, 1, 4), 2);
        assert_eq!(pixel_key(0, 3, 3, 4), 15);
        assert_eq!(pixel_key(1, 0, 0, 4), 256);
        assert!(pixel_key(1, 0, 0, 4) > pixel_key(0, 15, 15, 4));
    }

    #[test]
    fn key_bits_cover_the_largest_coordinate() {
        let img = vec![0u8; 4 * 37 * 23];
        let s = set(std::slice::from_ref(&img), 37, 23);
        assert_eq!(s.key_bits(), 6);
        let one = vec![0u8; 4];
        assert_eq!(set(std::slice::from_ref(&one), 1, 1).key_bits(), 0);
        let img = vec![0u8; 4 * 64];
        assert_eq!(set(std::slice::from_ref(&img), 64, 1).key_bits(), 6);
    }

    /// χ² of 4 views × 16 pixel bins (each bin a 4×4 tile of a 16×16 image) for 2^16 rays: 63
    /// degrees of freedom, and the 0.1 % critical value is 103.4 (a correct sampler fails one seed
    /// in a thousand; the seeds are fixed). Every run of the batch is sorted.
    #[test]
    fn draws_are_uniform_over_views_and_pixels_and_runs_sorted() {
        let (w, h, views) = (16u32, 16u32, 4usize);
        let images: Vec<Vec<u8>> = (0..views).map(|_| vec![0u8; 4 * 256]).collect();
        let s = set(&images, w, h);
        let n = 1usize << 16;
        for seed in [1u64, 0xdead_beef] {
            let b = sample_rays(&s, seed, n).unwrap();
            let mut bins = vec![0f64; views * 16];
            for &k in &b.keys {
                let (v, x, y) = key_pixel(k, s.key_bits());
                assert!((v as usize) < views && x < w && y < h);
                bins[v as usize * 16 + (y / 4 * 4 + x / 4) as usize] += 1.0;
            }
            let e = n as f64 / bins.len() as f64;
            let chi2: f64 = bins.iter().map(|&o| (o - e) * (o - e) / e).sum();
            assert!(chi2 < 103.4, "seed {seed}: χ² = {chi2:.1} over 63 dof");
            for run in b.keys.chunks(SAMPLE_SORT_RAYS as usize) {
                assert!(run.windows(2).all(|p| p[0] <= p[1]));
            }
            // The batch starts in view 0 and ends in view 3.
            assert_eq!(key_pixel(b.keys[0], s.key_bits()).0, 0);
            assert_eq!(key_pixel(b.keys[n - 1], s.key_bits()).0, 3);
        }
    }

    #[test]
    fn same_seed_same_batch_prefix_and_targets_are_the_pixels() {
        let (w, h) = (5u32, 3u32);
        let img: Vec<u8> = (0..4 * w * h).map(|i| (i * 7 % 256) as u8).collect();
        let s = set(std::slice::from_ref(&img), w, h);
        let a = sample_rays(&s, 42, 100).unwrap();
        assert_eq!(a, sample_rays(&s, 42, 100).unwrap());
        assert_ne!(a.keys, sample_rays(&s, 43, 100).unwrap().keys);
        for (i, &k) in a.keys.iter().enumerate() {
            let (_, x, y) = key_pixel(k, s.key_bits());
            let at = 4 * (y * w + x) as usize;
            for c in 0..3 {
                assert_eq!(a.targets[3 * i + c], img[at + c] as f32 / 255.0);
            }
            let d = &a.rays[6 * i + 3..6 * i + 6];
            let len = d.iter().map(|v| v * v).sum::<f32>().sqrt();
            assert!((len - 1.0).abs() < 1e-6);
        }
    }

    #[test]
    fn covered_pixels_are_alpha_above_zero_grown_by_the_radius() {
        let (w, h) = (8u32, 6u32);
        let mut a = vec![0u8; 4 * 48];
        a[4 * 16 + 3] = 1; // (0, 2): the square is cut at the left edge
        let mut b = vec![0u8; 4 * 48];
        b[4 * (5 * 8 + 7) + 3] = 255; // (7, 5): the bottom-right corner
        let f = Focus::covered(&[&a, &b], w, h, 1, 0.5).unwrap();
        let want: Vec<u32> = [
            (0, 0, 1),
            (0, 0, 2),
            (0, 0, 3),
            (0, 1, 1),
            (0, 1, 2),
            (0, 1, 3),
        ]
        .iter()
        .chain(&[(1, 6, 4), (1, 7, 4), (1, 6, 5), (1, 7, 5)])
        .map(|&(v, x, y)| v * 48 + y * 8 + x)
        .collect();
        let mut got = f.pixels().to_vec();
        got.sort_unstable();
        let mut want = want;
        want.sort_unstable();
        assert_eq!(got, want);
        assert_eq!(f.threshold(), 1 << 31);
        // Radius 0: the pixels themselves; alpha everywhere, or a share of 0: no focus.
        let f0 = Focus::covered(&[&a, &b], w, h, 0, 0.5).unwrap();
        assert_eq!(f0.pixels(), &[16, 48 + 47]);
        let opaque = vec![255u8; 4 * 48];
        assert!(Focus::covered(&[&opaque], w, h, 0, 0.5).unwrap().is_none());
        assert!(Focus::covered(&[&a], w, h, 1, 0.0).unwrap().is_none());
        assert!(Focus::covered(&[&a], w, h, 1, 1.5).is_err());
        assert!(Focus::covered(&[&a], w, h, 1, 1.0).is_err());
        assert!(Focus::new(vec![48], 0.5, 48).is_err());
    }

    #[test]
    fn a_focus_draws_its_share_from_its_pixels_and_none_draws_as_before() {
        let (w, h) = (16u32, 16u32);
        let images: Vec<Vec<u8>> = (0..2).map(|_| vec![0u8; 4 * 256]).collect();
        let mut s = set(&images, w, h);
        let n = 1usize << 16;
        let uniform = sample_rays(&s, 7, n).unwrap();
        // A focus of 10 pixels of view 1 with share 0.75: those pixels get 0.75 + 0.25·10/512 of
        // the rays, each of them equally often; the rest stay uniform over all 512.
        let focus: Vec<u32> = (0..10).map(|i| 256 + 25 * i).collect();
        s.focus = Focus::new(focus.clone(), 0.75, 512).unwrap();
        let b = sample_rays(&s, 7, n).unwrap();
        let mut counts = [0f64; 10];
        let mut outside = 0f64;
        for &k in &b.keys {
            let (v, x, y) = key_pixel(k, s.key_bits());
            let p = v * 256 + y * w + x;
            match focus.iter().position(|&f| f == p) {
                Some(j) => counts[j] += 1.0,
                None => outside += 1.0,
            }
        }
        let share = counts.iter().sum::<f64>() / n as f64;
        let want = 0.75 + 0.25 * 10.0 / 512.0;
        // 5 standard deviations of a binomial share over 65536 rays: 0.0085.
        assert!(
            (share - want).abs() < 0.0085,
            "focus share {share}, want {want}"
        );
        let e = counts.iter().sum::<f64>() / 10.0;
        let chi2: f64 = counts.iter().map(|&o| (o - e) * (o - e) / e).sum();
        assert!(chi2 < 27.9, "χ² = {chi2:.1} over 9 dof");
        assert!(outside > 0.0);
        // Importance weights: 1/512 over each pixel's probability, so the weighted draw is
        // uniform: the weights of the batch average 1, and the focus pixels' weighted share is
        // their uniform share 10/512.
        let (w_focus, w_other) = s.focus.weights();
        let p_focus = 0.75 / 10.0 + 0.25 / 512.0;
        assert!((w_focus as f64 - (1.0 / 512.0) / p_focus).abs() < 1e-7);
        assert_eq!(w_other, 4.0);
        assert_eq!(b.weights.len(), n);
        for (&k, &wt) in b.keys.iter().zip(&b.weights) {
            let (v, x, y) = key_pixel(k, s.key_bits());
            let hit = focus.contains(&(v * 256 + y * w + x));
            assert_eq!(wt, if hit { w_focus } else { w_other });
        }
        let mean_w = b.weights.iter().map(|&w| w as f64).sum::<f64>() / n as f64;
        let focus_w = counts.iter().sum::<f64>() * w_focus as f64 / n as f64;
        // Standard deviations over 65536 rays: 0.0067 for the mean weight, 4.4e-5 for the share.
        assert!((mean_w - 1.0).abs() < 0.025, "mean weight {mean_w}");
        assert!(
            (focus_w - 10.0 / 512.0).abs() < 2.5e-4,
            "weighted focus share {focus_w}"
        );
        assert!(uniform.weights.is_empty());
        // No focus: the uniform batch, bit for bit.
        s.focus = Focus::none();
        assert_eq!(sample_rays(&s, 7, n).unwrap(), uniform);
        // A focus made for another set is refused.
        s.focus = Focus::new(focus, 0.75, 256 * 3).unwrap();
        assert!(sample_rays(&s, 7, 16).is_err());
    }

    #[test]
    fn bad_sets_and_batches_are_errors() {
        let img = vec![0u8; 4 * 6];
        let mut s = set(std::slice::from_ref(&img), 3, 2);
        assert!(sample_rays(&s, 1, 0).is_err());
        s.cams.clear();
        assert!(sample_rays(&s, 1, 4).is_err());
        let s = set(&[], 3, 2);
        assert!(sample_rays(&s, 1, 4).is_err());
    }
}
