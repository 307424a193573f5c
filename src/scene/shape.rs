//! Analytic shapes of the procedural scenes, in f64: ray intersection (every boundary crossing,
//! so semi-transparent shells are composited front and back), area, area-uniform sampling,
//! strict containment (to drop ground-truth samples buried inside other solids) and bounds.

use glam::DVec3;
use rand::Rng;
use serde_json::{json, Value};
use std::f64::consts::PI;

/// A surface: closed convex solids (sphere, capsule, box) or zero-thickness, double-sided planar
/// patches (quad, ellipse).
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    /// Sphere.
    Sphere {
        /// Centre.
        centre: DVec3,
        /// Radius.
        radius: f64,
    },
    /// Cylinder from `a` to `b` with hemispherical caps (wires, stems).
    Capsule {
        /// One end of the axis.
        a: DVec3,
        /// The other end.
        b: DVec3,
        /// Radius.
        radius: f64,
    },
    /// Oriented box.
    Cuboid {
        /// Centre.
        centre: DVec3,
        /// Orthonormal axes.
        axes: [DVec3; 3],
        /// Half extents along the axes.
        half: DVec3,
    },
    /// Parallelogram `centre + s·u + t·v`, |s|, |t| ≤ 1, with u ⟂ v; zero thickness.
    Quad {
        /// Centre.
        centre: DVec3,
        /// Half-edge vector.
        u: DVec3,
        /// Half-edge vector, orthogonal to `u`.
        v: DVec3,
    },
    /// Ellipse `centre + s·u + t·v`, s² + t² ≤ 1, with u ⟂ v; zero thickness (leaves, discs).
    Ellipse {
        /// Centre.
        centre: DVec3,
        /// Semi-axis vector.
        u: DVec3,
        /// Semi-axis vector, orthogonal to `u`.
        v: DVec3,
    },
}

/// A ray–surface crossing: distance and geometric unit normal (either orientation).
#[derive(Clone, Copy, Debug)]
pub struct Crossing {
    /// Distance along the unit ray.
    pub t: f64,
    /// Unit normal.
    pub n: DVec3,
}

/// Ray interval inside a convex solid, with entry and exit normals.
type Interval = (f64, DVec3, f64, DVec3);

fn sphere_interval(o: DVec3, d: DVec3, c: DVec3, r: f64) -> Option<Interval> {
    let oc = o - c;
    let b = oc.dot(d);
    let q = oc - b * d; // closest-approach offset: numerically stable for thin spheres
    let disc = r * r - q.length_squared();
    if disc < 0.0 {
        return None;
    }
    let s = disc.sqrt();
    let (t0, t1) = (-b - s, -b + s);
    Some((t0, (o + t0 * d - c) / r, t1, (o + t1 * d - c) / r))
}

fn capsule_interval(o: DVec3, d: DVec3, a: DVec3, b: DVec3, r: f64) -> Option<Interval> {
    let axis = b - a;
    let len = axis.length();
    let w = axis / len;
    let mut best: Option<Interval> = None;
    let mut merge = |iv: Interval| {
        best = Some(match best {
            None => iv,
            Some(cur) => {
                let (t0, n0) = if iv.0 < cur.0 {
                    (iv.0, iv.1)
                } else {
                    (cur.0, cur.1)
                };
                let (t1, n1) = if iv.2 > cur.2 {
                    (iv.2, iv.3)
                } else {
                    (cur.2, cur.3)
                };
                (t0, n0, t1, n1)
            }
        })
    };
    if let Some(iv) = sphere_interval(o, d, a, r) {
        merge(iv);
    }
    if let Some(iv) = sphere_interval(o, d, b, r) {
        merge(iv);
    }
    // Finite cylinder: infinite cylinder ∩ slab 0 ≤ (p − a)·w ≤ len.
    let oc = o - a;
    let (dw, ow) = (d.dot(w), oc.dot(w));
    let dp = d - dw * w;
    let op = oc - ow * w;
    let aa = dp.length_squared();
    if aa > 1e-18 {
        let bb = dp.dot(op);
        let cc = op.length_squared() - r * r;
        let disc = bb * bb - aa * cc;
        if disc >= 0.0 {
            let s = disc.sqrt();
            let (mut t0, mut t1) = ((-bb - s) / aa, (-bb + s) / aa);
            let (s0, s1) = if dw.abs() > 1e-15 {
                let (x, y) = (-ow / dw, (len - ow) / dw);
                (x.min(y), x.max(y))
            } else if (0.0..=len).contains(&ow) {
                (f64::NEG_INFINITY, f64::INFINITY)
            } else {
                (1.0, -1.0)
            };
            t0 = t0.max(s0);
            t1 = t1.min(s1);
            if t0 <= t1 {
                let nrm = |t: f64| {
                    let p = o + t * d - a;
                    (p - p.dot(w) * w).normalize_or(w)
                };
                merge((t0, nrm(t0), t1, nrm(t1)));
            }
        }
    }
    best
}

fn cuboid_interval(
    o: DVec3,
    d: DVec3,
    c: DVec3,
    axes: &[DVec3; 3],
    half: DVec3,
) -> Option<Interval> {
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    let (mut n0, mut n1) = (DVec3::X, DVec3::X);
    for i in 0..3 {
        let ol = (o - c).dot(axes[i]);
        let dl = d.dot(axes[i]);
        if dl.abs() < 1e-15 {
            if ol.abs() > half[i] {
                return None;
            }
            continue;
        }
        let (mut a, mut b) = ((-half[i] - ol) / dl, (half[i] - ol) / dl);
        let (mut na, mut nb) = (-axes[i], axes[i]);
        if a > b {
            std::mem::swap(&mut a, &mut b);
            std::mem::swap(&mut na, &mut nb);
        }
        if a > t0 {
            t0 = a;
            n0 = na;
        }
        if b < t1 {
            t1 = b;
            n1 = nb;
        }
    }
    (t0 <= t1).then_some((t0, n0, t1, n1))
}

/// Orthonormal vectors perpendicular to unit `w`.
pub fn perpendiculars(w: DVec3) -> (DVec3, DVec3) {
    let e1 = w.any_orthonormal_vector();
    (e1, w.cross(e1))
}

fn unit_sphere_sample<R: Rng>(rng: &mut R) -> DVec3 {
    let z = 1.0 - 2.0 * rng.random::<f64>();
    let phi = 2.0 * PI * rng.random::<f64>();
    let s = (1.0 - z * z).max(0.0).sqrt();
    DVec3::new(s * phi.cos(), s * phi.sin(), z)
}

fn v3(v: DVec3) -> Value {
    json!([v.x, v.y, v.z])
}

impl Shape {
    /// Pushes every crossing with t > `tmin` of the unit-direction ray o + t·d.
    pub fn crossings(&self, o: DVec3, d: DVec3, tmin: f64, out: &mut Vec<Crossing>) {
        let interval = match self {
            Shape::Sphere { centre, radius } => sphere_interval(o, d, *centre, *radius),
            Shape::Capsule { a, b, radius } => capsule_interval(o, d, *a, *b, *radius),
            Shape::Cuboid { centre, axes, half } => cuboid_interval(o, d, *centre, axes, *half),
            Shape::Quad { centre, u, v } | Shape::Ellipse { centre, u, v } => {
                let n = u.cross(*v);
                let denom = d.dot(n);
                if denom.abs() <= 1e-15 * n.length() {
                    return;
                }
                let t = (*centre - o).dot(n) / denom;
                if t <= tmin {
                    return;
                }
                let p = o + t * d - *centre;
                let s = p.dot(*u) / u.length_squared();
                let r = p.dot(*v) / v.length_squared();
                let inside = match self {
                    Shape::Quad { .. } => s.abs() <= 1.0 && r.abs() <= 1.0,
                    _ => s * s + r * r <= 1.0,
                };
                if inside {
                    out.push(Crossing {
                        t,
                        n: n.normalize(),
                    });
                }
                return;
            }
        };
        if let Some((t0, n0, t1, n1)) = interval {
            if t0 > tmin {
                out.push(Crossing { t: t0, n: n0 });
            }
            if t1 > tmin {
                out.push(Crossing { t: t1, n: n1 });
            }
        }
    }

    /// Surface area.
    pub fn area(&self) -> f64 {
        match self {
            Shape::Sphere { radius, .. } => 4.0 * PI * radius * radius,
            Shape::Capsule { a, b, radius } => {
                2.0 * PI * radius * (*b - *a).length() + 4.0 * PI * radius * radius
            }
            Shape::Cuboid { half, .. } => {
                8.0 * (half.x * half.y + half.y * half.z + half.x * half.z)
            }
            Shape::Quad { u, v, .. } => 4.0 * u.length() * v.length(),
            Shape::Ellipse { u, v, .. } => PI * u.length() * v.length(),
        }
    }

    /// A point uniformly distributed by area on the surface.
    pub fn sample<R: Rng>(&self, rng: &mut R) -> DVec3 {
        match self {
            Shape::Sphere { centre, radius } => *centre + *radius * unit_sphere_sample(rng),
            Shape::Capsule { a, b, radius } => {
                let len = (*b - *a).length();
                let w = (*b - *a) / len;
                let side = 2.0 * PI * radius * len;
                if rng.random::<f64>() * self.area() < side {
                    let (e1, e2) = perpendiculars(w);
                    let s = rng.random::<f64>() * len;
                    let phi = 2.0 * PI * rng.random::<f64>();
                    *a + s * w + *radius * (phi.cos() * e1 + phi.sin() * e2)
                } else {
                    let q = unit_sphere_sample(rng);
                    (if q.dot(w) >= 0.0 { *b } else { *a }) + *radius * q
                }
            }
            Shape::Cuboid { centre, axes, half } => {
                let faces = [half.y * half.z, half.x * half.z, half.x * half.y];
                let mut pick = rng.random::<f64>() * (faces[0] + faces[1] + faces[2]);
                let mut k = 0;
                while k < 2 && pick >= faces[k] {
                    pick -= faces[k];
                    k += 1;
                }
                let sign = if rng.random::<bool>() { 1.0 } else { -1.0 };
                let mut p = *centre + sign * half[k] * axes[k];
                for j in (0..3).filter(|&j| j != k) {
                    p += (2.0 * rng.random::<f64>() - 1.0) * half[j] * axes[j];
                }
                p
            }
            Shape::Quad { centre, u, v } => {
                *centre
                    + (2.0 * rng.random::<f64>() - 1.0) * *u
                    + (2.0 * rng.random::<f64>() - 1.0) * *v
            }
            Shape::Ellipse { centre, u, v } => {
                let r = rng.random::<f64>().sqrt();
                let th = 2.0 * PI * rng.random::<f64>();
                *centre + r * th.cos() * *u + r * th.sin() * *v
            }
        }
    }

    /// Whether `p` lies strictly inside the solid (by more than 1e-7); always false for planar
    /// patches.
    pub fn contains(&self, p: DVec3) -> bool {
        const EPS: f64 = 1e-7;
        match self {
            Shape::Sphere { centre, radius } => (p - *centre).length() < radius - EPS,
            Shape::Capsule { a, b, radius } => {
                let ab = *b - *a;
                let s = ((p - *a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0);
                (p - (*a + s * ab)).length() < radius - EPS
            }
            Shape::Cuboid { centre, axes, half } => {
                (0..3).all(|i| (p - *centre).dot(axes[i]).abs() < half[i] - EPS)
            }
            Shape::Quad { .. } | Shape::Ellipse { .. } => false,
        }
    }

    /// Whether the shape is a closed solid.
    pub fn is_closed(&self) -> bool {
        !matches!(self, Shape::Quad { .. } | Shape::Ellipse { .. })
    }

    /// Axis-aligned bounds (min, max).
    pub fn aabb(&self) -> (DVec3, DVec3) {
        let (c, e) = match self {
            Shape::Sphere { centre, radius } => (*centre, DVec3::splat(*radius)),
            Shape::Capsule { a, b, radius } => {
                return (
                    a.min(*b) - DVec3::splat(*radius),
                    a.max(*b) + DVec3::splat(*radius),
                );
            }
            Shape::Cuboid { centre, axes, half } => (
                *centre,
                axes[0].abs() * half.x + axes[1].abs() * half.y + axes[2].abs() * half.z,
            ),
            Shape::Quad { centre, u, v } => (*centre, u.abs() + v.abs()),
            Shape::Ellipse { centre, u, v } => (*centre, (*u * *u + *v * *v).map(f64::sqrt)),
        };
        (c - e, c + e)
    }

    /// Sets of 8 corners of boxes that together enclose the shape (for screen-space culling).
    /// Long capsules are split into pieces so thin diagonal wires get tight bounds.
    pub fn bound_boxes(&self) -> Vec<[DVec3; 8]> {
        let obb = |c: DVec3, a: [DVec3; 3]| -> [DVec3; 8] {
            std::array::from_fn(|k| {
                let s = |bit: usize| if k >> bit & 1 == 1 { 1.0 } else { -1.0 };
                c + s(0) * a[0] + s(1) * a[1] + s(2) * a[2]
            })
        };
        match self {
            Shape::Capsule { a, b, radius } => {
                let ab = *b - *a;
                let len = ab.length();
                let w = ab / len;
                let (e1, e2) = perpendiculars(w);
                let n = ((len / (4.0 * radius)).ceil() as usize).clamp(1, 64);
                (0..n)
                    .map(|k| {
                        let c = *a + ab * ((k as f64 + 0.5) / n as f64);
                        obb(
                            c,
                            [
                                w * (0.5 * len / n as f64 + radius),
                                e1 * *radius,
                                e2 * *radius,
                            ],
                        )
                    })
                    .collect()
            }
            Shape::Cuboid { centre, axes, half } => {
                vec![obb(
                    *centre,
                    [axes[0] * half.x, axes[1] * half.y, axes[2] * half.z],
                )]
            }
            Shape::Quad { centre, u, v } | Shape::Ellipse { centre, u, v } => {
                let n = u.cross(*v).normalize() * 1e-6;
                vec![obb(*centre, [*u, *v, n])]
            }
            Shape::Sphere { .. } => {
                let (lo, hi) = self.aabb();
                let (c, e) = ((lo + hi) * 0.5, (hi - lo) * 0.5);
                vec![obb(c, [DVec3::X * e.x, DVec3::Y * e.y, DVec3::Z * e.z])]
            }
        }
    }

    /// A JSON description for `scene.json`.
    pub fn describe(&self) -> Value {
        match self {
            Shape::Sphere { centre, radius } => {
                json!({"type": "sphere", "centre": v3(*centre), "radius": radius})
            }
            Shape::Capsule { a, b, radius } => {
                json!({"type": "capsule", "a": v3(*a), "b": v3(*b), "radius": radius})
            }
            Shape::Cuboid { centre, axes, half } => json!({"type": "box", "centre": v3(*centre),
                "axes": [v3(axes[0]), v3(axes[1]), v3(axes[2])], "half_extents": v3(*half)}),
            Shape::Quad { centre, u, v } => {
                json!({"type": "quad", "centre": v3(*centre), "u": v3(*u), "v": v3(*v)})
            }
            Shape::Ellipse { centre, u, v } => {
                json!({"type": "ellipse", "centre": v3(*centre), "u": v3(*u), "v": v3(*v)})
            }
        }
    }
}
