//! Rays for training and rendering: a seeded sampler of uniform ray batches over all pixels of a
//! split (with replacement; deterministic for a seed), and the rays of a whole view. Rays are in
//! the scaled world (Blender units × `SceneBox::scale`) with unit directions.

use super::camera::SceneBox;
use super::dataset::Split;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// A batch of rays with their target colours (composited on the background) and alpha.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RayBatch {
    /// Ray origins, scaled world.
    pub origins: Vec<[f32; 3]>,
    /// Unit directions.
    pub dirs: Vec<[f32; 3]>,
    /// Target colour in [0, 1].
    pub rgb: Vec<[f32; 3]>,
    /// Target alpha in [0, 1].
    pub alpha: Vec<f32>,
}

impl RayBatch {
    /// Number of rays.
    pub fn len(&self) -> usize {
        self.origins.len()
    }

    /// The rays as the kernels take them: 6 floats each (origin, unit direction).
    pub fn flat_rays(&self) -> Vec<f32> {
        self.origins
            .iter()
            .zip(&self.dirs)
            .flat_map(|(o, d)| o.iter().chain(d).copied())
            .collect()
    }

    /// The target colours, 3 floats per ray.
    pub fn flat_targets(&self) -> Vec<f32> {
        self.rgb.iter().flatten().copied().collect()
    }

    /// Whether the batch is empty.
    pub fn is_empty(&self) -> bool {
        self.origins.is_empty()
    }

    fn push(&mut self, split: &Split, scene: &SceneBox, view: usize, x: u32, y: u32) {
        let f = &split.frames[view];
        let (o, d) = f.camera.pixel_ray(x, y);
        self.origins.push(scene.to_scaled(o).to_array());
        self.dirs.push(d.to_array());
        self.rgb.push(f.image.rgb(x, y));
        self.alpha.push(f.image.alpha(x, y));
    }
}

/// One pixel of a split.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PixelRef {
    /// View index.
    pub view: u32,
    /// Column.
    pub x: u32,
    /// Row.
    pub y: u32,
}

/// Uniform random pixels (with replacement) over every view of a split; deterministic for a seed.
pub struct RaySampler {
    rng: Pcg64,
    width: u32,
    height: u32,
    n_pixels: u64,
}

impl RaySampler {
    /// A sampler over `split`'s pixels.
    pub fn new(split: &Split, seed: u64) -> RaySampler {
        RaySampler {
            rng: Pcg64::seed_from_u64(seed),
            width: split.width(),
            height: split.height(),
            n_pixels: split.n_pixels(),
        }
    }

    /// The next `n` pixels, drawn independently, then ordered by view and Z-order within the
    /// view: neighbouring invocations of a kernel then trace nearby rays (the walks diverge less;
    /// docs/tuning.md). The order changes no loss: a batch's gradient is a sum over its rays.
    pub fn sample_pixels(&mut self, n: usize) -> Vec<PixelRef> {
        let per_view = self.width as u64 * self.height as u64;
        let mut px: Vec<PixelRef> = (0..n)
            .map(|_| {
                let i = self.rng.random_range(0..self.n_pixels);
                let (view, rest) = (i / per_view, i % per_view);
                PixelRef {
                    view: view as u32,
                    x: (rest % self.width as u64) as u32,
                    y: (rest / self.width as u64) as u32,
                }
            })
            .collect();
        px.sort_unstable_by_key(|p| (p.view, morton2(p.x, p.y)));
        px
    }

    /// The next batch of `n` rays with their targets.
    pub fn next_batch(&mut self, split: &Split, scene: &SceneBox, n: usize) -> RayBatch {
        let mut b = RayBatch::default();
        for p in self.sample_pixels(n) {
            b.push(split, scene, p.view as usize, p.x, p.y);
        }
        b
    }
}

/// Interleaved bits of `x` and `y` (Z-order), so pixels close in the image are close in the key.
fn morton2(x: u32, y: u32) -> u64 {
    fn spread(v: u32) -> u64 {
        let mut v = v as u64;
        v = (v | (v << 16)) & 0x0000_ffff_0000_ffff;
        v = (v | (v << 8)) & 0x00ff_00ff_00ff_00ff;
        v = (v | (v << 4)) & 0x0f0f_0f0f_0f0f_0f0f;
        v = (v | (v << 2)) & 0x3333_3333_3333_3333;
        (v | (v << 1)) & 0x5555_5555_5555_5555
    }
    spread(x) | (spread(y) << 1)
}

/// Every ray of one view, row by row.
pub fn view_rays(split: &Split, scene: &SceneBox, view: usize) -> RayBatch {
    let mut b = RayBatch::default();
    for y in 0..split.height() {
        for x in 0..split.width() {
            b.push(split, scene, view, x, y);
        }
    }
    b
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn morton_interleaves_x_then_y() {
        assert_eq!(morton2(0, 0), 0);
        assert_eq!(morton2(1, 0), 1);
        assert_eq!(morton2(0, 1), 2);
        assert_eq!(morton2(3, 3), 15);
        assert_eq!(morton2(0xffff, 0), 0x5555_5555);
        assert_eq!(morton2(u32::MAX, u32::MAX), u64::MAX);
    }

    #[test]
    fn pixels_come_sorted_by_view_and_z_order() {
        let mut s = RaySampler {
            rng: Pcg64::seed_from_u64(5),
            width: 37,
            height: 23,
            n_pixels: 37 * 23 * 4,
        };
        let px = s.sample_pixels(3000);
        assert_eq!(px.len(), 3000);
        assert!(px
            .windows(2)
            .all(|w| (w[0].view, morton2(w[0].x, w[0].y)) <= (w[1].view, morton2(w[1].x, w[1].y))));
        assert!(px.iter().all(|p| p.view < 4 && p.x < 37 && p.y < 23));
        // The order runs across all four views.
        assert_eq!(px.last().unwrap().view, 3);
        assert_eq!(px[0].view, 0);
    }
}
