//! The built-in scenes, built in code (Blender units, +Z up, all inside [−1.5, 1.5]³):
//! - `thin`: a frame strung with wires of radius 0.004–0.008 (diameter ≤ 0.016, under 1/100 of
//!   the 3-unit scene) and a potted plant with zero-thickness leaves seen from both sides;
//! - `translucent`: two nested semi-transparent spherical shells (alpha 0.3 and 0.45) around an
//!   opaque toy (box, ball, handle);
//! - `solid`: a simple opaque figure (box base, two balls, two capsule arms).
//!
//! Random details (wire radii, leaf placement, texture phases) come from a PCG stream of the seed.

use super::material::{Material, Texture};
use super::shape::Shape;
use super::{Object, Scene};
use glam::{DMat3, DVec3};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// Which built-in scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum SceneKind {
    /// Wires on a frame and a plant with zero-thickness leaves.
    Thin,
    /// Nested semi-transparent shells with an opaque object inside.
    Translucent,
    /// A simple opaque object.
    Solid,
}

impl SceneKind {
    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            SceneKind::Thin => "thin",
            SceneKind::Translucent => "translucent",
            SceneKind::Solid => "solid",
        }
    }
}

/// Builds a built-in scene; deterministic for `seed`.
pub fn build(kind: SceneKind, seed: u64) -> Scene {
    let mut rng = Pcg64::seed_from_u64(seed ^ 0x5eed_5ce4e);
    let objects = match kind {
        SceneKind::Thin => thin(&mut rng),
        SceneKind::Translucent => translucent(&mut rng),
        SceneKind::Solid => solid(&mut rng),
    };
    Scene {
        name: kind.name().into(),
        objects,
        light: DVec3::new(0.45, -0.35, 0.82).normalize(),
    }
}

fn rgb(r: f64, g: f64, b: f64) -> DVec3 {
    DVec3::new(r, g, b)
}

fn opaque(colors: [DVec3; 2], texture: Texture) -> Material {
    Material {
        alpha: 1.0,
        colors,
        texture,
    }
}

/// Wires thinner than this (1/100 of the 3-unit scene) are flagged `thin`.
pub const THIN_DIAMETER: f64 = 0.03;

fn obj(name: impl Into<String>, shape: Shape, material: Material) -> Object {
    let thin = matches!(shape, Shape::Capsule { radius, .. } if 2.0 * radius < THIN_DIAMETER);
    Object {
        name: name.into(),
        shape,
        material,
        thin,
    }
}

fn aligned_box(centre: DVec3, half: DVec3) -> Shape {
    Shape::Cuboid {
        centre,
        axes: [DVec3::X, DVec3::Y, DVec3::Z],
        half,
    }
}

fn rotated_box(centre: DVec3, half: DVec3, rot: DMat3) -> Shape {
    Shape::Cuboid {
        centre,
        axes: [rot.x_axis, rot.y_axis, rot.z_axis],
        half,
    }
}

/// Corners of the wire frame in the XZ plane: (x0, x1, z0, z1).
const THIN_FRAME: (f64, f64, f64, f64) = (-1.0, 0.3, -0.85, 0.85);

fn thin<R: Rng>(rng: &mut R) -> Vec<Object> {
    let mut v = Vec::new();
    // Order matters: the frame bars and then the leaves draw from `rng`.
    thin_frame_bars(rng, &mut v);
    thin_wires(&mut v);
    let stem_pts = thin_pot_and_stem(&mut v);
    thin_leaves(rng, &stem_pts, &mut v);
    v
}

/// The four wooden bars of the frame; each draws one wood-grain phase from `rng`.
fn thin_frame_bars<R: Rng>(rng: &mut R, v: &mut Vec<Object>) {
    let wood = |rng: &mut R| {
        opaque(
            [rgb(0.45, 0.25, 0.10), rgb(0.25, 0.12, 0.05)],
            Texture::Waves {
                freq: 9.0,
                phase: rng.random::<f64>() * 6.0,
            },
        )
    };
    // Frame in the XZ plane: x ∈ [−1.04, 0.34], z ∈ [−0.9, 0.9].
    let (x0, x1, z0, z1) = THIN_FRAME;
    let xm = 0.5 * (x0 + x1);
    let hx = 0.5 * (x1 - x0) + 0.04;
    v.push(obj(
        "frame_bottom",
        aligned_box(DVec3::new(xm, 0.0, z0), DVec3::new(hx, 0.04, 0.05)),
        wood(rng),
    ));
    v.push(obj(
        "frame_top",
        aligned_box(DVec3::new(xm, 0.0, z1), DVec3::new(hx, 0.04, 0.05)),
        wood(rng),
    ));
    v.push(obj(
        "frame_left",
        aligned_box(DVec3::new(x0, 0.0, 0.0), DVec3::new(0.04, 0.04, 0.8)),
        wood(rng),
    ));
    v.push(obj(
        "frame_right",
        aligned_box(DVec3::new(x1, 0.0, 0.0), DVec3::new(0.04, 0.04, 0.8)),
        wood(rng),
    ));
}

/// The vertical and diagonal wires strung across the frame (no random draws).
fn thin_wires(v: &mut Vec<Object>) {
    let (x0, x1, z0, z1) = THIN_FRAME;
    // Nine vertical wires, radius 0.004–0.008, ends buried in the bars.
    let metal = [rgb(0.75, 0.72, 0.55), rgb(0.35, 0.33, 0.30)];
    for k in 0..9 {
        let x = x0 + 0.13 + (x1 - x0 - 0.26) * k as f64 / 8.0;
        let r = 0.004 + 0.004 * k as f64 / 8.0;
        let shape = Shape::Capsule {
            a: DVec3::new(x, 0.0, z0),
            b: DVec3::new(x, 0.0, z1),
            radius: r,
        };
        v.push(obj(
            format!("wire_{k}"),
            shape,
            opaque(
                metal,
                Texture::Stripes {
                    dir: DVec3::Z,
                    freq: 40.0,
                },
            ),
        ));
    }
    // Two diagonal wires in front of the vertical ones (no contact).
    for (k, (za, zb)) in [(z0 + 0.05, z1 - 0.05), (z1 - 0.05, z0 + 0.05)]
        .into_iter()
        .enumerate()
    {
        let y = -0.02 - 0.015 * k as f64;
        let shape = Shape::Capsule {
            a: DVec3::new(x0 + 0.04, y, za),
            b: DVec3::new(x1 - 0.04, y, zb),
            radius: 0.005,
        };
        let mat = opaque(
            [rgb(0.15, 0.30, 0.75), rgb(0.70, 0.80, 0.95)],
            Texture::Stripes {
                dir: DVec3::X,
                freq: 30.0,
            },
        );
        v.push(obj(format!("diagonal_{k}"), shape, mat));
    }
}

/// Material shared by the plant's stem segments and leaf petioles.
fn thin_stem_material() -> Material {
    opaque(
        [rgb(0.25, 0.45, 0.15), rgb(0.40, 0.55, 0.20)],
        Texture::Stripes {
            dir: DVec3::Z,
            freq: 25.0,
        },
    )
}

/// The pot and the three stem segments of the potted plant at x = 0.85;
/// returns the stem polyline the leaves hang from.
fn thin_pot_and_stem(v: &mut Vec<Object>) -> [DVec3; 4] {
    let base = DVec3::new(0.85, 0.0, -0.68);
    v.push(obj(
        "pot",
        aligned_box(DVec3::new(0.85, 0.0, -0.8), DVec3::new(0.17, 0.17, 0.12)),
        opaque(
            [rgb(0.70, 0.35, 0.20), rgb(0.50, 0.22, 0.12)],
            Texture::Checker { freq: 30.0 },
        ),
    ));
    let stem_pts = [
        base,
        DVec3::new(0.82, 0.03, -0.2),
        DVec3::new(0.88, -0.02, 0.25),
        DVec3::new(0.84, 0.0, 0.6),
    ];
    let stem_mat = thin_stem_material();
    for k in 0..3 {
        let shape = Shape::Capsule {
            a: stem_pts[k],
            b: stem_pts[k + 1],
            radius: 0.012,
        };
        v.push(obj(format!("stem_{k}"), shape, stem_mat.clone()));
    }
    stem_pts
}

/// Twenty-four leaves (a petiole capsule and a zero-thickness elliptical blade
/// each) placed along `stem_pts`; draws seven values from `rng` per leaf.
fn thin_leaves<R: Rng>(rng: &mut R, stem_pts: &[DVec3; 4], v: &mut Vec<Object>) {
    let stem_mat = thin_stem_material();
    let leaf_colors = [rgb(0.10, 0.45, 0.10), rgb(0.45, 0.75, 0.20)];
    for k in 0..24 {
        // A point on the stem polyline above the pot.
        let s = 0.15 + 0.85 * (k as f64 + rng.random::<f64>()) / 24.0;
        let seg = ((s * 3.0) as usize).min(2);
        let f = s * 3.0 - seg as f64;
        let on_stem = stem_pts[seg].lerp(stem_pts[seg + 1], f);
        let az = k as f64 * 2.39996 + rng.random::<f64>() * 0.5; // golden-angle phyllotaxis
        let rise = 0.25 + 0.35 * rng.random::<f64>();
        let out = DVec3::new(az.cos(), az.sin(), rise).normalize();
        let petiole = 0.05 + 0.05 * rng.random::<f64>();
        let tip = on_stem + out * petiole;
        v.push(obj(
            format!("petiole_{k}"),
            Shape::Capsule {
                a: on_stem,
                b: tip,
                radius: 0.004,
            },
            stem_mat.clone(),
        ));
        let half_len = 0.07 + 0.05 * rng.random::<f64>();
        let half_wid = 0.025 + 0.02 * rng.random::<f64>();
        let side = out.cross(DVec3::Z).normalize();
        // Tilt the leaf blade about its midrib.
        let tilt = (rng.random::<f64>() - 0.5) * 1.2;
        let across = (side * tilt.cos() + out.cross(side).normalize() * tilt.sin()).normalize();
        let shape = Shape::Ellipse {
            centre: tip + out * half_len,
            u: out * half_len,
            v: across * half_wid,
        };
        let mat = opaque(
            leaf_colors,
            Texture::Stripes {
                dir: side,
                freq: 90.0,
            },
        );
        v.push(obj(format!("leaf_{k}"), shape, mat));
    }
}

fn translucent<R: Rng>(rng: &mut R) -> Vec<Object> {
    let mut v = Vec::new();
    v.push(obj(
        "shell_outer",
        Shape::Sphere {
            centre: DVec3::new(0.0, 0.0, 0.05),
            radius: 0.85,
        },
        Material {
            alpha: 0.3,
            colors: [rgb(0.55, 0.75, 0.95), rgb(0.90, 0.95, 1.0)],
            texture: Texture::Stripes {
                dir: DVec3::new(0.3, 0.2, 0.93).normalize(),
                freq: 14.0,
            },
        },
    ));
    v.push(obj(
        "shell_inner",
        Shape::Sphere {
            centre: DVec3::new(0.03, -0.02, 0.0),
            radius: 0.55,
        },
        Material {
            alpha: 0.45,
            colors: [rgb(0.95, 0.65, 0.15), rgb(0.95, 0.85, 0.55)],
            texture: Texture::Checker { freq: 12.0 },
        },
    ));
    let rot = DMat3::from_rotation_z(0.5) * DMat3::from_rotation_x(0.3);
    let phase = rng.random::<f64>() * 6.0;
    v.push(obj(
        "toy_box",
        rotated_box(DVec3::new(0.0, 0.0, -0.12), DVec3::splat(0.17), rot),
        opaque(
            [rgb(0.80, 0.10, 0.10), rgb(0.25, 0.05, 0.30)],
            Texture::Waves { freq: 10.0, phase },
        ),
    ));
    v.push(obj(
        "toy_ball",
        Shape::Sphere {
            centre: DVec3::new(0.02, 0.0, 0.2),
            radius: 0.14,
        },
        opaque(
            [rgb(0.10, 0.30, 0.80), rgb(0.85, 0.85, 0.20)],
            Texture::Checker { freq: 25.0 },
        ),
    ));
    v.push(obj(
        "toy_handle",
        Shape::Capsule {
            a: DVec3::new(-0.3, 0.05, -0.25),
            b: DVec3::new(0.32, -0.05, 0.1),
            radius: 0.03,
        },
        opaque(
            [rgb(0.15, 0.60, 0.25), rgb(0.90, 0.90, 0.90)],
            Texture::Stripes {
                dir: DVec3::X,
                freq: 40.0,
            },
        ),
    ));
    v
}

fn solid<R: Rng>(rng: &mut R) -> Vec<Object> {
    let phase = rng.random::<f64>() * 6.0;
    let rot = DMat3::from_rotation_z(0.35);
    vec![
        obj(
            "base",
            rotated_box(
                DVec3::new(0.0, 0.0, -0.62),
                DVec3::new(0.45, 0.32, 0.12),
                rot,
            ),
            opaque(
                [rgb(0.30, 0.30, 0.35), rgb(0.65, 0.60, 0.50)],
                Texture::Waves { freq: 8.0, phase },
            ),
        ),
        obj(
            "body",
            Shape::Sphere {
                centre: DVec3::new(0.0, 0.0, -0.12),
                radius: 0.42,
            },
            opaque(
                [rgb(0.85, 0.80, 0.70), rgb(0.55, 0.35, 0.20)],
                Texture::Checker { freq: 14.0 },
            ),
        ),
        obj(
            "head",
            Shape::Sphere {
                centre: DVec3::new(0.03, -0.02, 0.48),
                radius: 0.24,
            },
            opaque(
                [rgb(0.90, 0.60, 0.40), rgb(0.40, 0.20, 0.50)],
                Texture::Waves {
                    freq: 12.0,
                    phase: phase + 1.0,
                },
            ),
        ),
        obj(
            "arm_left",
            Shape::Capsule {
                a: DVec3::new(-0.3, 0.0, 0.0),
                b: DVec3::new(-0.72, 0.12, 0.38),
                radius: 0.06,
            },
            opaque(
                [rgb(0.20, 0.55, 0.30), rgb(0.80, 0.85, 0.30)],
                Texture::Stripes {
                    dir: DVec3::Z,
                    freq: 35.0,
                },
            ),
        ),
        obj(
            "arm_right",
            Shape::Capsule {
                a: DVec3::new(0.3, 0.0, 0.0),
                b: DVec3::new(0.70, -0.10, -0.30),
                radius: 0.06,
            },
            opaque(
                [rgb(0.20, 0.55, 0.30), rgb(0.80, 0.85, 0.30)],
                Texture::Stripes {
                    dir: DVec3::Z,
                    freq: 35.0,
                },
            ),
        ),
    ]
}
