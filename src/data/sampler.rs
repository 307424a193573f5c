//! Rays for training and rendering: a seeded sampler of uniform ray batches over all pixels of a
//! split (with replacement; deterministic for a seed), and the rays of a whole view. Rays are in
//! the scaled world (Blender units × `SceneBox::scale`) with unit directions.

use super::camera::SceneBox;
use super::dataset::Split;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// A batch of rays with their target colours (composited on white) and alpha.
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

    /// The next `n` pixels.
    pub fn sample_pixels(&mut self, n: usize) -> Vec<PixelRef> {
        let per_view = self.width as u64 * self.height as u64;
        (0..n)
            .map(|_| {
                let i = self.rng.random_range(0..self.n_pixels);
                let (view, rest) = (i / per_view, i % per_view);
                PixelRef {
                    view: view as u32,
                    x: (rest % self.width as u64) as u32,
                    y: (rest / self.width as u64) as u32,
                }
            })
            .collect()
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
