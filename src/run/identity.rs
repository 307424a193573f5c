//! A dataset's identity as a run records it: a content fingerprint (every split's image names,
//! sizes, camera poses and a sample of their pixels) and the scene normalisation the run trained
//! with, which `--resume` and `--init` compare with the dataset they are given
//! ([`super::same_data`]).

use crate::data::Dataset;
use serde::{Deserialize, Serialize};

/// What `run.json` records of the dataset beside its path (see the module documentation).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DataIdentity {
    /// FNV-1a (64-bit, hex) over every split's name and, per view, its image file name, image
    /// size, camera-to-world matrix (f32 bits) and [`PIXEL_SAMPLES`] of its pixels (two scenes
    /// rendered from the same cameras differ only there; their alpha, and their colour where
    /// opaque, so the background they are composited on does not enter).
    pub fingerprint: String,
    /// The scene box's centre (scaled units).
    pub scene_centre: [f32; 3],
    /// The scene box's half-size (scaled units).
    pub scene_radius: f32,
}

impl DataIdentity {
    /// The identity of a loaded dataset.
    pub fn of(data: &Dataset) -> DataIdentity {
        let mut h = Fnv1a::new();
        for split in data.splits() {
            h.write(split.name.as_bytes());
            h.write(&[0]);
            for f in &split.frames {
                let name = f.file.file_name().unwrap_or_default();
                h.write(name.to_string_lossy().as_bytes());
                h.write(&[0]);
                h.write(&f.image.width.to_le_bytes());
                h.write(&f.image.height.to_le_bytes());
                for v in f.camera.c2w.to_cols_array() {
                    h.write(&v.to_bits().to_le_bytes());
                }
                let pixels = f.image.data.chunks_exact(4);
                let stride = (pixels.len() / PIXEL_SAMPLES).max(1);
                // Alpha, and the colour where it is opaque: what the background (a run's own
                // choice, checked on its own) does not change.
                for p in pixels.step_by(stride) {
                    h.write(if p[3] == 255 { p } else { &p[3..] });
                }
            }
        }
        DataIdentity {
            fingerprint: format!("{:016x}", h.0),
            scene_centre: data.scene.centre.to_array(),
            scene_radius: data.scene.radius,
        }
    }
}

/// Pixels per view that enter the fingerprint, evenly spaced (cheap next to loading).
pub const PIXEL_SAMPLES: usize = 4096;

/// FNV-1a, 64-bit: a stable hash (the standard library's may change between releases).
struct Fnv1a(u64);

impl Fnv1a {
    fn new() -> Self {
        Fnv1a(0xcbf2_9ce4_8422_2325)
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 ^ b as u64).wrapping_mul(0x0100_0000_01b3);
        }
    }
}
