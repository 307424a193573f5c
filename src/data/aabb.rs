//! Axis-aligned boxes in dataset (world) units: the `--box xmin,ymin,zmin,xmax,ymax,zmax` of
//! `train`, `extract` and `eval`, a scene's `eval_box`, the foreground box found from the cameras
//! and the box a run records.

use super::scene_box::SceneBox;
use anyhow::{ensure, Result};
use glam::Vec3;
use serde::{Deserialize, Serialize};

/// An axis-aligned box, dataset units.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Aabb {
    /// Lower corner.
    pub min: [f32; 3],
    /// Upper corner.
    pub max: [f32; 3],
}

impl Aabb {
    /// The box between two corners.
    pub fn new(min: Vec3, max: Vec3) -> Aabb {
        Aabb {
            min: min.to_array(),
            max: max.to_array(),
        }
    }

    /// The box a flag gives as `xmin,ymin,zmin,xmax,ymax,zmax`: six finite numbers, each minimum
    /// below its maximum; errors name `flag`.
    pub fn from_values(flag: &str, v: &[f32]) -> Result<Aabb> {
        ensure!(
            v.len() == 6,
            "{flag}: expected six numbers xmin,ymin,zmin,xmax,ymax,zmax, got {}",
            v.len()
        );
        ensure!(
            v.iter().all(|x| x.is_finite()),
            "{flag}: every value must be finite, got {v:?}"
        );
        let b = Aabb {
            min: [v[0], v[1], v[2]],
            max: [v[3], v[4], v[5]],
        };
        ensure!(
            (0..3).all(|a| b.min[a] < b.max[a]),
            "{flag}: each minimum must be below its maximum, got min {:?}, max {:?}",
            b.min,
            b.max
        );
        Ok(b)
    }

    /// Lower corner.
    pub fn lo(&self) -> Vec3 {
        Vec3::from_array(self.min)
    }

    /// Upper corner.
    pub fn hi(&self) -> Vec3 {
        Vec3::from_array(self.max)
    }

    /// Whether `p` lies in the box (faces included).
    pub fn contains(&self, p: [f32; 3]) -> bool {
        (0..3).all(|a| self.min[a] <= p[a] && p[a] <= self.max[a])
    }

    /// The scene normalisation whose grid cube encloses the box: centred on it, as wide as its
    /// widest side.
    pub fn scene_box(&self) -> SceneBox {
        let (lo, hi) = (self.lo(), self.hi());
        let half = (0.5 * (hi - lo).max_element()).max(f32::MIN_POSITIVE);
        let scale = 1.0 / half;
        SceneBox {
            scale,
            centre: 0.5 * (lo + hi) * scale,
            radius: 1.0,
            ndc: None,
        }
    }

    /// The grid cube of a scene normalisation.
    pub fn of_scene(scene: &SceneBox) -> Aabb {
        let (lo, hi) = scene.blender_bounds();
        Aabb::new(lo, hi)
    }
}

impl std::fmt::Display for Aabb {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let v = |p: [f32; 3]| format!("[{:.3}, {:.3}, {:.3}]", p[0], p[1], p[2]);
        write!(f, "{} .. {}", v(self.min), v(self.max))
    }
}
