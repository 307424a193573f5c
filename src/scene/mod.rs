//! Procedural scenes with exact ground truth: analytic shapes ([`shape`]), materials
//! ([`material`]), the built-in scenes ([`builtin`]: thin, translucent, solid), an exact CPU ray
//! caster ([`render`]) and the writer of NeRF-synthetic datasets with `gt_points.ply` and
//! `scene.json` ([`generate`]). Scene coordinates are Blender units, +Z up.

pub mod builtin;
pub mod generate;
pub mod material;
pub mod render;
pub mod shape;

pub use builtin::{build, SceneKind};
pub use generate::{generate, GenerateOptions, GenerateReport};
pub use material::{Material, Texture};
pub use render::render_view;
pub use shape::Shape;

use glam::DVec3;

/// Half-size of the box every object must fit in (Blender units): the default grid box after
/// the 2/3 scale.
pub const SCENE_HALF_EXTENT: f64 = 1.5;

/// One object: a shape with a material.
#[derive(Clone, Debug)]
pub struct Object {
    /// Name (unique in the scene).
    pub name: String,
    /// Geometry.
    pub shape: Shape,
    /// Appearance.
    pub material: Material,
    /// Whether it is a thin structure (a wire or stem thinner than 1/100 of the scene size).
    pub thin: bool,
}

impl Object {
    /// Whether it blocks light completely (alpha 1).
    pub fn opaque(&self) -> bool {
        self.material.alpha >= 1.0
    }
}

/// A scene: objects and a directional light.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Scene name ("thin", "translucent", "solid").
    pub name: String,
    /// Its objects.
    pub objects: Vec<Object>,
    /// Unit direction towards the light.
    pub light: DVec3,
}

impl Scene {
    /// Union of the objects' bounds.
    pub fn aabb(&self) -> (DVec3, DVec3) {
        self.objects.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), o| {
                let (a, b) = o.shape.aabb();
                (lo.min(a), hi.max(b))
            },
        )
    }

    /// Total surface area.
    pub fn area(&self) -> f64 {
        self.objects.iter().map(|o| o.shape.area()).sum()
    }
}
