//! The analytic shapes: crossings agree with containment, samples lie on the surface, rays
//! aimed at samples hit them, and sampling is uniform by area.

use alphasurf::scene::shape::{Crossing, Shape};
use glam::{DMat3, DVec3};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

fn shapes() -> Vec<Shape> {
    let rot = DMat3::from_rotation_z(0.4) * DMat3::from_rotation_x(0.7);
    vec![
        Shape::Sphere {
            centre: DVec3::new(0.1, -0.2, 0.3),
            radius: 0.5,
        },
        Shape::Capsule {
            a: DVec3::new(-0.5, 0.1, -0.3),
            b: DVec3::new(0.6, -0.2, 0.4),
            radius: 0.006,
        },
        Shape::Capsule {
            a: DVec3::new(-0.2, 0.0, 0.0),
            b: DVec3::new(0.3, 0.1, 0.05),
            radius: 0.2,
        },
        Shape::Cuboid {
            centre: DVec3::new(0.0, 0.1, -0.1),
            axes: [rot.x_axis, rot.y_axis, rot.z_axis],
            half: DVec3::new(0.3, 0.2, 0.1),
        },
        Shape::Quad {
            centre: DVec3::ZERO,
            u: DVec3::new(0.3, 0.0, 0.1),
            v: DVec3::new(0.0, 0.2, 0.0),
        },
        Shape::Ellipse {
            centre: DVec3::new(0.1, 0.0, 0.0),
            u: DVec3::new(0.0, 0.0, 0.3),
            v: DVec3::new(0.1, 0.05, 0.0),
        },
    ]
}

/// Distance from `p` to the surface, computed independently of the intersection code.
fn surface_distance(s: &Shape, p: DVec3) -> f64 {
    match s {
        Shape::Sphere { centre, radius } => ((p - *centre).length() - radius).abs(),
        Shape::Capsule { a, b, radius } => {
            let ab = *b - *a;
            let t = ((p - *a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0);
            ((p - (*a + t * ab)).length() - radius).abs()
        }
        Shape::Cuboid { centre, axes, half } => {
            let l = DVec3::new(
                (p - *centre).dot(axes[0]),
                (p - *centre).dot(axes[1]),
                (p - *centre).dot(axes[2]),
            );
            let q = l.abs() - *half;
            // On the surface: max(q) = 0 with every q ≤ 0.
            if q.max_element() <= 1e-12 {
                -q.max_element()
            } else {
                q.max(DVec3::ZERO).length()
            }
        }
        Shape::Quad { centre, u, v } | Shape::Ellipse { centre, u, v } => {
            let n = u.cross(*v).normalize();
            let d = p - *centre;
            let (s1, s2) = (
                d.dot(*u) / u.length_squared(),
                d.dot(*v) / v.length_squared(),
            );
            let inside = if matches!(s, Shape::Quad { .. }) {
                s1.abs() <= 1.0 + 1e-9 && s2.abs() <= 1.0 + 1e-9
            } else {
                s1 * s1 + s2 * s2 <= 1.0 + 1e-9
            };
            if inside {
                d.dot(n).abs()
            } else {
                f64::INFINITY
            }
        }
    }
}

#[test]
fn samples_lie_on_the_surface_and_rays_hit_them() {
    let mut rng = Pcg64::seed_from_u64(1);
    for s in shapes() {
        let mut hits: Vec<Crossing> = Vec::new();
        for _ in 0..2000 {
            let p = s.sample(&mut rng);
            assert!(
                surface_distance(&s, p) < 1e-9,
                "{s:?}: sample {p} off the surface"
            );
            // Aim a ray from a random far point at the sample: some crossing is at the sample.
            let from = p + 3.0
                * DVec3::new(
                    rng.random::<f64>() - 0.5,
                    rng.random::<f64>() - 0.5,
                    rng.random::<f64>() - 0.5,
                )
                .normalize();
            let d = (p - from).normalize();
            hits.clear();
            s.crossings(from, d, 0.0, &mut hits);
            let t = (p - from).length();
            assert!(
                hits.iter().any(|h| (h.t - t).abs() < 1e-7),
                "{s:?}: ray to {p} misses ({hits:?})"
            );
            for h in &hits {
                assert!(
                    surface_distance(&s, from + h.t * d) < 1e-7,
                    "{s:?}: crossing off the surface"
                );
                assert!((h.n.length() - 1.0).abs() < 1e-9);
            }
        }
    }
}

#[test]
fn crossings_agree_with_containment() {
    let mut rng = Pcg64::seed_from_u64(2);
    for s in shapes().into_iter().filter(Shape::is_closed) {
        let (lo, hi) = s.aabb();
        let mut hits = Vec::new();
        for _ in 0..3000 {
            let target = lo + (hi - lo) * DVec3::new(rng.random(), rng.random(), rng.random());
            let o = target + DVec3::new(2.0, 1.3, -0.7);
            let d = (target - o).normalize();
            hits.clear();
            s.crossings(o, d, 0.0, &mut hits);
            assert!(
                hits.is_empty() || hits.len() == 2,
                "convex: 0 or 2 crossings"
            );
            // Walk the ray: inside exactly between the two crossings.
            for k in 0..50 {
                let t = 1.5 + 3.0 * k as f64 / 50.0;
                let inside = hits.len() == 2 && t > hits[0].t + 1e-9 && t < hits[1].t - 1e-9;
                let near = hits.iter().any(|h| (h.t - t).abs() < 1e-6);
                if !near {
                    assert_eq!(s.contains(o + t * d), inside, "{s:?} at t = {t}");
                }
            }
        }
    }
}

#[test]
fn areas_match_monte_carlo_hits() {
    // Cauchy–Crofton-style check: for a convex solid, the fraction of random lines from a big
    // sphere that hit it is proportional to its surface area; compare two shapes' ratios.
    let mut rng = Pcg64::seed_from_u64(3);
    let shapes = shapes();
    let (sphere, cuboid) = (&shapes[0], &shapes[3]);
    let (mut hs, mut hc) = (0u32, 0u32);
    let mut buf = Vec::new();
    for _ in 0..400_000 {
        let dir = |rng: &mut Pcg64| {
            let z: f64 = 2.0 * rng.random::<f64>() - 1.0;
            let phi = std::f64::consts::TAU * rng.random::<f64>();
            let r = (1.0 - z * z).sqrt();
            DVec3::new(r * phi.cos(), r * phi.sin(), z)
        };
        let d = dir(&mut rng);
        let (e1, e2) = alphasurf::scene::shape::perpendiculars(d);
        let (u, v) = (
            2.0 * rng.random::<f64>() - 1.0,
            2.0 * rng.random::<f64>() - 1.0,
        );
        let o = (u * e1 + v * e2) * 1.5 - 5.0 * d;
        buf.clear();
        sphere.crossings(o, d, 0.0, &mut buf);
        hs += !buf.is_empty() as u32;
        buf.clear();
        cuboid.crossings(o, d, 0.0, &mut buf);
        hc += !buf.is_empty() as u32;
    }
    let ratio = hc as f64 / hs as f64;
    let want = cuboid.area() / sphere.area();
    assert!(
        (ratio / want - 1.0).abs() < 0.02,
        "hit ratio {ratio} vs area ratio {want}"
    );
}
