//! Surface appearance: layer opacity, two colours blended by a smooth procedural solid texture
//! (so photometric reconstruction has something to match), and simple diffuse shading.

use glam::DVec3;
use serde_json::{json, Value};

/// Solid-texture pattern in [0, 1] evaluated at world position.
#[derive(Clone, Debug, PartialEq)]
pub enum Texture {
    /// 0.5 + 0.5·sin(freq·p·dir).
    Stripes {
        /// Stripe normal (unit).
        dir: DVec3,
        /// Angular frequency, radians per unit.
        freq: f64,
    },
    /// 0.5 + 0.5·sin(f·x)·sin(f·y)·sin(f·z): a smooth 3-D checker.
    Checker {
        /// Angular frequency.
        freq: f64,
    },
    /// Four octaves of sines along fixed directions with a phase offset: a cheap smooth noise.
    Waves {
        /// Base angular frequency.
        freq: f64,
        /// Phase offset (varies per object).
        phase: f64,
    },
}

const WAVE_DIRS: [[f64; 3]; 4] = [
    [0.80, 0.36, 0.48],
    [-0.28, 0.91, 0.30],
    [0.12, -0.40, 0.91],
    [0.67, -0.67, -0.32],
];

impl Texture {
    /// Pattern value in [0, 1] at `p`.
    pub fn value(&self, p: DVec3) -> f64 {
        match self {
            Texture::Stripes { dir, freq } => 0.5 + 0.5 * (freq * p.dot(*dir)).sin(),
            Texture::Checker { freq } => {
                0.5 + 0.5 * (freq * p.x).sin() * (freq * p.y).sin() * (freq * p.z).sin()
            }
            Texture::Waves { freq, phase } => {
                let mut s = 0.0;
                let mut amp = 1.0;
                let mut f = *freq;
                for (k, d) in WAVE_DIRS.iter().enumerate() {
                    s += amp * (f * p.dot(DVec3::from_array(*d)) + phase * (k + 1) as f64).sin();
                    amp *= 0.5;
                    f *= 2.0;
                }
                0.5 + 0.5 * s / 1.875
            }
        }
    }

    fn describe(&self) -> Value {
        match self {
            Texture::Stripes { dir, freq } => {
                json!({"type": "stripes", "dir": [dir.x, dir.y, dir.z], "freq": freq})
            }
            Texture::Checker { freq } => json!({"type": "checker", "freq": freq}),
            Texture::Waves { freq, phase } => {
                json!({"type": "waves", "freq": freq, "phase": phase})
            }
        }
    }
}

/// Appearance of one object.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Opacity of one surface layer (1 = opaque). Every crossing of the surface is composited
    /// with this alpha (a closed semi-transparent shell is seen twice).
    pub alpha: f64,
    /// The two colours the texture blends, in [0, 1].
    pub colors: [DVec3; 2],
    /// The blend pattern.
    pub texture: Texture,
}

/// Ambient term of the shading.
pub const AMBIENT: f64 = 0.35;
/// Diffuse term of the shading.
pub const DIFFUSE: f64 = 0.65;

impl Material {
    /// Shaded colour at `p` with unit normal `n`, seen along unit direction `d`, lit by the unit
    /// direction towards the light `light`: albedo·(AMBIENT + DIFFUSE·max(0, n_f·light)), n_f the
    /// normal turned towards the viewer (every surface is double-sided).
    pub fn shade(&self, p: DVec3, n: DVec3, d: DVec3, light: DVec3) -> DVec3 {
        let s = self.texture.value(p);
        let albedo = self.colors[0] * (1.0 - s) + self.colors[1] * s;
        let nf = if n.dot(d) > 0.0 { -n } else { n };
        albedo * (AMBIENT + DIFFUSE * nf.dot(light).max(0.0))
    }

    /// A JSON description for `scene.json`.
    pub fn describe(&self) -> Value {
        let c = |v: DVec3| json!([v.x, v.y, v.z]);
        json!({"alpha": self.alpha, "colors": [c(self.colors[0]), c(self.colors[1])], "texture": self.texture.describe()})
    }
}
