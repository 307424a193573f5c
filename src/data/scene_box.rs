//! The scene box: how dataset units map to the grid's space (a scaled box, or a forward-facing
//! capture's NDC), and the rays and sampler cameras in that space.

use super::camera::Camera;
use super::ndc::Ndc;
use crate::abi::buffers::SampleCamera;
use glam::Vec3;

/// Scene normalisation: the scaled world is Blender units × `scale`; the grid box is
/// `centre ± radius` in scaled units. Default: scale 2/3, centre 0, radius 1, so the grid box
/// [−1, 1]³ covers [−1.5, 1.5]³ Blender units. A forward-facing capture in NDC
/// ([`SceneBox::in_ndc`]) has the NDC cube as its grid box and rays carried into NDC.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneBox {
    /// Blender → scaled world factor.
    pub scale: f32,
    /// Box centre, scaled units.
    pub centre: Vec3,
    /// Box half-size, scaled units.
    pub radius: f32,
    /// The NDC space the grid lies in instead of the scaled world.
    pub ndc: Option<Ndc>,
}

impl Default for SceneBox {
    fn default() -> Self {
        SceneBox {
            scale: 2.0 / 3.0,
            centre: Vec3::ZERO,
            radius: 1.0,
            ndc: None,
        }
    }
}

impl SceneBox {
    /// The grid over the NDC cube [−1, 1]³ of `ndc`.
    pub fn in_ndc(ndc: Ndc) -> SceneBox {
        SceneBox {
            scale: 1.0,
            centre: Vec3::ZERO,
            radius: 1.0,
            ndc: Some(ndc),
        }
    }

    /// The ray (origin, unit direction; 6 floats as the kernels take it) in the grid's space of
    /// the ray from `o` along unit `d`, Blender units.
    pub fn ray(&self, o: Vec3, d: Vec3) -> [f32; 6] {
        match &self.ndc {
            Some(ndc) => ndc.ray(o, d),
            None => {
                let o = self.to_scaled(o);
                [o.x, o.y, o.z, d.x, d.y, d.z]
            }
        }
    }

    /// A camera as the ray sampler takes it (`abi::rays::SampleSet`): in the scaled world, or
    /// in the NDC frame.
    pub fn sample_camera(&self, c: &Camera) -> SampleCamera {
        match &self.ndc {
            Some(ndc) => ndc.sample_camera(c),
            None => {
                let m = c.c2w;
                SampleCamera {
                    x_axis: m.x_axis.truncate().to_array(),
                    y_axis: m.y_axis.truncate().to_array(),
                    z_axis: m.z_axis.truncate().to_array(),
                    origin: self.to_scaled(c.centre()).to_array(),
                    focal: [c.fx, c.fy],
                    centre: [c.cx, c.cy],
                }
            }
        }
    }

    /// Blender units → scaled world.
    pub fn to_scaled(&self, p: Vec3) -> Vec3 {
        p * self.scale
    }

    /// Scaled world → Blender units.
    pub fn to_blender(&self, p: Vec3) -> Vec3 {
        p / self.scale
    }

    /// The grid box in Blender units (min, max).
    pub fn blender_bounds(&self) -> (Vec3, Vec3) {
        (
            self.to_blender(self.centre - Vec3::splat(self.radius)),
            self.to_blender(self.centre + Vec3::splat(self.radius)),
        )
    }
}
