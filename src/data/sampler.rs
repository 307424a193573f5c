//! Rays for training and rendering: a split's views as the seeded sampler of training batches
//! reads them (uniform over all pixels of the split with replacement, or with a share from the
//! pixels the object covers; deterministic for a seed),
//! and the rays of a whole view. Rays are in the grid's space (the scaled world, Blender units ×
//! `SceneBox::scale`, or a forward-facing capture's NDC) with unit directions.

use super::scene_box::SceneBox;
use super::split::Split;
use crate::abi::rays::{Focus, SampleSet};
use crate::gpu::TrainRays;
use anyhow::{Context, Result};
use std::sync::atomic::{AtomicU64, Ordering};

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
        let r = scene.ray(o, d);
        self.origins.push([r[0], r[1], r[2]]);
        self.dirs.push([r[3], r[4], r[5]]);
        self.rgb.push(f.image.rgb(x, y));
        self.alpha.push(f.image.alpha(x, y));
    }
}

/// Covered pixels grow by this many pixels in [`TrainViews::focused`]: a thin part that a grid
/// renders a little too wide shows on the background pixels beside it, which the focus then
/// samples as well.
pub const FOCUS_GROW: u32 = 2;

static NEXT_ID: AtomicU64 = AtomicU64::new(1);

/// A split's training views as the ray sampler reads them (`cpu::sample_rays`, and the device
/// copy the Vulkan backends keep of it): every view's image (borrowed) and its camera in the
/// scaled world. Each set has an id of its own, so a backend uploads one set once per run.
pub struct TrainViews<'a> {
    id: u64,
    set: SampleSet<'a>,
}

impl<'a> TrainViews<'a> {
    /// The views of `split` in the scaled world of `scene`. Errors name the split's source when
    /// its images cannot be sampled (over 65536 pixels per axis).
    pub fn new(split: &'a Split, scene: &SceneBox) -> Result<TrainViews<'a>> {
        let set = SampleSet {
            width: split.width(),
            height: split.height(),
            images: split
                .frames
                .iter()
                .map(|f| f.image.data.as_slice())
                .collect(),
            cams: split
                .frames
                .iter()
                .map(|f| scene.sample_camera(&f.camera))
                .collect(),
            focus: Focus::none(),
            ndc: scene.ndc.map(|n| n.projection),
        };
        set.validate()
            .with_context(|| format!("{} split of {}", split.name, split.source.display()))?;
        Ok(TrainViews {
            id: NEXT_ID.fetch_add(1, Ordering::Relaxed),
            set,
        })
    }

    /// The same views with a share `share` ∈ [0, 1) of each batch drawn from the pixels the
    /// object covers (alpha above 0, grown by [`FOCUS_GROW`] pixels; `abi::rays::Focus`),
    /// the rest uniform over all pixels. Views without alpha, or a share of 0, draw uniformly.
    /// The result is a set of its own (a new [`id`](Self::id)).
    pub fn focused(mut self, share: f32) -> Result<TrainViews<'a>> {
        let s = &self.set;
        self.set.focus = Focus::covered(&s.images, s.width, s.height, FOCUS_GROW, share)?;
        self.id = NEXT_ID.fetch_add(1, Ordering::Relaxed);
        Ok(self)
    }

    /// Identifies this set among those made in this process.
    pub fn id(&self) -> u64 {
        self.id
    }

    /// The images and cameras.
    pub fn set(&self) -> &SampleSet<'a> {
        &self.set
    }

    /// The batch of `n` rays drawn with `seed` from these views, as a Vulkan backend's training
    /// step takes it (drawn on the device).
    pub fn train_rays(&self, seed: u64, n: usize) -> TrainRays<'_> {
        TrainRays::Sampled {
            id: self.id,
            set: &self.set,
            seed,
            n,
        }
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
