//! Training-ray batches as the host and the kernels draw them: the pixels and cameras a batch is
//! drawn from ([`SampleSet`], with its [`Focus`]), the sorted pixel keys of a seeded draw
//! ([`sorted_keys`]: `glsl/sample_rays.comp`'s pass 0 and `glsl/sample_rays_sort.comp`, bit for
//! bit) and a drawn batch ([`SampledRays`]). The rays of the keys are written by `sample_rays`'s
//! pass 1 (twin `cpu::sample_rays`).

use crate::abi::buffers::SampleCamera;
use crate::abi::consts::SAMPLE_SORT_RAYS;
use anyhow::{ensure, Result};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The constants of the NDC map of a forward-facing capture (`math::ndc`, `glsl/lib/ndc.glsl`):
/// the near plane's depth `near` (> 0, the NDC frame's units) and the frame camera's 2·f_x/W and
/// 2·f_y/H.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct NdcProjection {
    pub near: f32,
    pub sx: f32,
    pub sy: f32,
}

/// The pixels and cameras a batch is drawn from: every view's RGBA8 image (composited colour,
/// 4 bytes per pixel, row-major, the u32 per pixel the kernel reads) and camera.
pub struct SampleSet<'a> {
    pub width: u32,
    pub height: u32,
    /// One `width·height·4`-byte image per view.
    pub images: Vec<&'a [u8]>,
    pub cams: Vec<SampleCamera>,
    /// Pixels a share of each batch is drawn from ([`Focus::none`]: every ray uniform).
    pub focus: Focus,
    /// A forward-facing capture's NDC map, the cameras given in its frame: each ray is carried
    /// into NDC (`math::ndc::ndc_ray`). `None`: rays in the scaled world.
    pub ndc: Option<NdcProjection>,
}

/// Pixels that a share of each batch is drawn from, uniformly among them; the rest of the batch
/// stays uniform over every pixel. Ray i is drawn from the focus pixels when the high 32 bits of
/// its hash h = splitmix64(seed, i) are below `threshold` (a share threshold / 2^32 of the
/// rays), as pixel `pixels[h mod len]`; otherwise as pixel h mod n_pixels.
///
/// Each ray carries an importance weight, the uniform draw's probability of its pixel over the
/// mixture's ([`weights`](Self::weights)), so that a batch's weighted loss is an unbiased
/// estimate of the uniform batch's: the focus lowers the variance on the object's pixels without
/// changing what training minimises.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Focus {
    pixels: Vec<u32>,
    threshold: u32,
    n_pixels: u64,
}

impl Focus {
    /// No focus: every ray uniform over all pixels.
    pub fn none() -> Focus {
        Focus::default()
    }

    /// A share `share` ∈ [0, 1) of each batch drawn from the set `pixels` (flat indices view·w·h +
    /// y·w + x into a set of `n_pixels` pixels, fewer than 2^32; sorted and deduplicated here).
    /// No pixels, or a share of 0, is no focus. A share of 1 would leave the other pixels
    /// undrawn, so it is refused.
    pub fn new(mut pixels: Vec<u32>, share: f32, n_pixels: u64) -> Result<Focus> {
        ensure!(
            (0.0..1.0).contains(&share),
            "the focus share must be in [0, 1), got {share}"
        );
        ensure!(
            (n_pixels <= 1 << 32 && pixels.len() <= u32::MAX as usize) || pixels.is_empty(),
            "a focus of {} pixels over {n_pixels}: at most 2^32 − 1 of 2^32",
            pixels.len()
        );
        if let Some(&p) = pixels.iter().find(|&&p| p as u64 >= n_pixels) {
            anyhow::bail!("focus pixel {p} is outside the set's {n_pixels} pixels");
        }
        let threshold = (share as f64 * 4_294_967_296.0)
            .round()
            .min(u32::MAX as f64) as u32;
        pixels.sort_unstable();
        pixels.dedup();
        if pixels.is_empty() || threshold == 0 || pixels.len() as u64 == n_pixels {
            return Ok(Focus::none());
        }
        Ok(Focus {
            pixels,
            threshold,
            n_pixels,
        })
    }

    /// The pixels of `images` (RGBA8 views of `width`×`height`) whose alpha is above 0, each
    /// grown by `radius` pixels to a (2·radius + 1)² square within its view, with a share
    /// `share` of each batch. Images without alpha (255 everywhere) cover every pixel, and every
    /// pixel covered is no focus: the draw is then uniform.
    pub fn covered(
        images: &[&[u8]],
        width: u32,
        height: u32,
        radius: u32,
        share: f32,
    ) -> Result<Focus> {
        let (w, h, r) = (width as usize, height as usize, radius as usize);
        let per_view = w * h;
        let n_pixels = (images.len() * per_view) as u64;
        let per_image: Vec<Vec<u32>> = images
            .par_iter()
            .enumerate()
            .map(|(v, img)| {
                let mut mask = vec![false; per_view];
                for y in 0..h {
                    for x in 0..w {
                        if img[4 * (y * w + x) + 3] == 0 {
                            continue;
                        }
                        for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                            mask[yy * w + x.saturating_sub(r)..yy * w + (x + r + 1).min(w)]
                                .fill(true);
                        }
                    }
                }
                let base = (v * per_view) as u32;
                (0..per_view as u32)
                    .filter(|&p| mask[p as usize])
                    .map(|p| base + p)
                    .collect()
            })
            .collect();
        Focus::new(per_image.concat(), share, n_pixels)
    }

    /// The focus pixels (flat indices, ascending).
    pub fn pixels(&self) -> &[u32] {
        &self.pixels
    }

    /// The importance weights (of a focus pixel, of any other): with share f of the rays drawn
    /// from k focus pixels out of N, a focus pixel is drawn with probability f/k + (1 − f)/N and
    /// any other with (1 − f)/N, against 1/N when uniform; each weight is 1/N over its
    /// probability. (1, 1) without a focus.
    pub fn weights(&self) -> (f32, f32) {
        if self.is_none() {
            return (1.0, 1.0);
        }
        let f = self.threshold as f64 / 4_294_967_296.0;
        let frac = self.pixels.len() as f64 / self.n_pixels as f64;
        (
            (1.0 / (f / frac + 1.0 - f)) as f32,
            (1.0 / (1.0 - f)) as f32,
        )
    }

    /// Whether the pixel with flat index `p` is a focus pixel.
    pub fn contains(&self, p: u64) -> bool {
        p <= u32::MAX as u64 && self.pixels.binary_search(&(p as u32)).is_ok()
    }

    /// Rays whose hash has its high 32 bits below this are drawn from the focus pixels.
    pub fn threshold(&self) -> u32 {
        self.threshold
    }

    /// Whether every ray is drawn uniformly.
    pub fn is_none(&self) -> bool {
        self.pixels.is_empty()
    }
}

impl SampleSet<'_> {
    /// Number of views.
    pub fn views(&self) -> u32 {
        self.images.len() as u32
    }

    /// Number of pixels over all views.
    pub fn n_pixels(&self) -> u64 {
        self.images.len() as u64 * self.width as u64 * self.height as u64
    }

    /// Bits of a pixel coordinate in a key: the least b with max(width, height) ≤ 2^b.
    pub fn key_bits(&self) -> u32 {
        32 - (self.width.max(self.height) - 1).leading_zeros()
    }

    /// Whether the kernel can sample this set: one camera and image per view, at least one pixel,
    /// coordinates of at most 16 bits (the key's Z-order half-words), fewer than 2^32 views.
    pub fn validate(&self) -> Result<()> {
        let bytes = 4 * self.width as usize * self.height as usize;
        ensure!(
            self.width > 0 && self.height > 0 && !self.images.is_empty(),
            "no pixels to sample rays from"
        );
        ensure!(
            self.width <= 1 << 16 && self.height <= 1 << 16,
            "images of {}×{} pixels: ray sampling takes at most 65536 per axis",
            self.width,
            self.height
        );
        ensure!(
            self.cams.len() == self.images.len() && self.images.iter().all(|i| i.len() == bytes),
            "{} cameras for {} images; every image must hold {bytes} bytes",
            self.cams.len(),
            self.images.len()
        );
        ensure!(
            self.focus.is_none() || self.focus.n_pixels == self.n_pixels(),
            "a focus made for {} pixels on a set of {}",
            self.focus.n_pixels,
            self.n_pixels()
        );
        if let Some(p) = self.ndc {
            let positive = |x: f32| x > 0.0 && x.is_finite();
            ensure!(
                positive(p.near) && positive(p.sx) && positive(p.sy),
                "an NDC map with near {}, 2f/W {}, 2f/H {}: each must be positive and finite",
                p.near,
                p.sx,
                p.sy
            );
        }
        Ok(())
    }
}

/// A sampled batch: per ray its sort key, ray (origin, unit direction) and target colour.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SampledRays {
    /// (view << 2·key_bits) | morton(x, y), ascending within each run of [`SAMPLE_SORT_RAYS`].
    pub keys: Vec<u64>,
    /// 6 floats per ray.
    pub rays: Vec<f32>,
    /// 3 floats per ray.
    pub targets: Vec<f32>,
    /// The importance weight of each ray ([`Focus::weights`]); empty without a focus (all 1).
    pub weights: Vec<f32>,
}

/// SplitMix64's output function on the counter `seed + (i + 1)·γ` (the kernel's, bit for bit).
pub fn splitmix64(seed: u64, i: u32) -> u64 {
    let mut z = seed.wrapping_add((i as u64 + 1).wrapping_mul(0x9e37_79b9_7f4a_7c15));
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The bits of `v` (< 2^16) spread to the even bit positions.
fn spread_bits(mut v: u32) -> u32 {
    v = (v | (v << 8)) & 0x00ff_00ff;
    v = (v | (v << 4)) & 0x0f0f_0f0f;
    v = (v | (v << 2)) & 0x3333_3333;
    (v | (v << 1)) & 0x5555_5555
}

/// Inverse of [`spread_bits`] on the even bits of `m`.
fn compact_bits(mut m: u32) -> u32 {
    m &= 0x5555_5555;
    m = (m | (m >> 1)) & 0x3333_3333;
    m = (m | (m >> 2)) & 0x0f0f_0f0f;
    m = (m | (m >> 4)) & 0x00ff_00ff;
    (m | (m >> 8)) & 0x0000_ffff
}

/// The key of pixel (x, y) of `view` with `bits`-bit coordinates.
pub fn pixel_key(view: u32, x: u32, y: u32, bits: u32) -> u64 {
    ((view as u64) << (2 * bits)) | (spread_bits(x) | (spread_bits(y) << 1)) as u64
}

/// The pixel (view, x, y) of a key.
pub fn key_pixel(key: u64, bits: u32) -> (u32, u32, u32) {
    let shift = 2 * bits;
    let morton = (key & ((1u64 << shift) - 1)) as u32;
    (
        (key >> shift) as u32,
        compact_bits(morton),
        compact_bits(morton >> 1),
    )
}

/// The key of ray `i` of the batch drawn with `seed`.
fn draw_key(set: &SampleSet, seed: u64, i: u32) -> u64 {
    let per_view = set.width as u64 * set.height as u64;
    let h = splitmix64(seed, i);
    let f = &set.focus;
    let p = if ((h >> 32) as u32) < f.threshold {
        f.pixels[(h % f.pixels.len() as u64) as usize] as u64
    } else {
        h % set.n_pixels()
    };
    let view = p / per_view;
    let rest = (p - view * per_view) as u32;
    pixel_key(
        view as u32,
        rest % set.width,
        rest / set.width,
        set.key_bits(),
    )
}

/// Sorts `keys` ascending in runs of [`SAMPLE_SORT_RAYS`] (the last may be shorter), as
/// `glsl/sample_rays_sort.comp` does (its twin `cpu::sample_rays_sort` is this sort).
pub fn sample_rays_sort(keys: &mut [u64]) {
    keys.par_chunks_mut(SAMPLE_SORT_RAYS as usize)
        .for_each(|r| r.sort_unstable());
}

/// The keys of the batch of `n` rays drawn with `seed`, sorted per run: the first two steps of
/// the draw (`sample_rays`'s pass 0 and `sample_rays_sort`; twin `cpu::sample_rays`).
pub fn sorted_keys(set: &SampleSet, seed: u64, n: usize) -> Result<Vec<u64>> {
    set.validate()?;
    ensure!(
        n > 0 && n <= u32::MAX as usize,
        "a batch of {n} rays (1 to 2^32 − 1)"
    );
    // A run per task: a default batch is one run, too little work to gain from splitting it
    // across threads.
    let mut keys: Vec<u64> = (0..n as u32)
        .into_par_iter()
        .with_min_len(SAMPLE_SORT_RAYS as usize)
        .map(|i| draw_key(set, seed, i))
        .collect();
    sample_rays_sort(&mut keys);
    Ok(keys)
}
