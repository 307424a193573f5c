//! Normalised device coordinates of a forward-facing capture (the map NeRF and svox2 train LLFF
//! scenes in): the twin of `glsl/lib/ndc.glsl`. In the NDC frame the reference camera looks down
//! −z; a point q (q.z < 0) maps to (−sx·q.x/q.z, −sy·q.y/q.z, 1 + 2n/q.z), so depth n (the near
//! plane) maps to z = −1 and infinite depth to z = +1, and the frame camera's view fills
//! [−1, 1] across. The map is projective: straight rays stay straight, which the closed-form
//! surface intersection needs.

use crate::abi::rays::NdcProjection;

/// The ray NDC assigns to a ray heading away from the frame camera's plane when one does not
/// (d.z ≥ 0, or NaN): it starts behind the NDC cube's far face and leaves it, so it meets nothing.
pub const MISSED_RAY: [f32; 6] = [0.0, 0.0, 3.0, 0.0, 0.0, 1.0];

/// The NDC ray of the ray from `o` along `d` (the NDC frame; `d` need not be unit): its origin
/// where it crosses the near plane (z = −1) and its unit direction, in the kernel's order of
/// operations (`glsl/lib/ndc.glsl`). Unnormalised, the direction is
/// (−sx·(d.x/d.z + o'.x/n), −sy·(d.y/d.z + o'.y/n), 2) with o' the crossing in the frame.
pub fn ndc_ray(o: [f32; 3], d: [f32; 3], p: NdcProjection) -> [f32; 6] {
    if !(d[2] < 0.0) {
        return MISSED_RAY;
    }
    let t = -(p.near + o[2]) / d[2];
    let ox = t.mul_add(d[0], o[0]) / p.near;
    let oy = t.mul_add(d[1], o[1]) / p.near;
    let (rx, ry) = (d[0] / d[2], d[1] / d[2]);
    let nd = [-p.sx * (rx + ox), -p.sy * (ry + oy), 2.0];
    let len2 = nd[0] * nd[0] + nd[1] * nd[1] + nd[2] * nd[2];
    let inv = 1.0 / len2.sqrt();
    [
        p.sx * ox,
        p.sy * oy,
        -1.0,
        nd[0] * inv,
        nd[1] * inv,
        nd[2] * inv,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    const P: NdcProjection = NdcProjection {
        near: 1.5,
        sx: 2.4,
        sy: 1.8,
    };

    /// The point map the ray map must agree with (f64).
    fn point(q: [f64; 3]) -> [f64; 3] {
        let (n, sx, sy) = (P.near as f64, P.sx as f64, P.sy as f64);
        [-sx * q[0] / q[2], -sy * q[1] / q[2], 1.0 + 2.0 * n / q[2]]
    }

    /// Every point of a ray in front of the near plane maps onto its NDC ray: the map sends
    /// lines to lines, and the NDC ray starts on the near plane.
    #[test]
    fn points_of_a_ray_lie_on_its_ndc_ray() {
        let o = [0.3f32, -0.2, 0.4];
        let d = [0.2f32, 0.1, -1.0];
        let r = ndc_ray(o, d, P);
        assert_eq!(r[2], -1.0);
        let (ro, rd) = (
            [r[0], r[1], r[2]].map(f64::from),
            [r[3], r[4], r[5]].map(f64::from),
        );
        assert!((rd.iter().map(|x| x * x).sum::<f64>() - 1.0).abs() < 1e-6);
        for u in [2.0f64, 3.0, 10.0, 1e4] {
            let q: [f64; 3] = std::array::from_fn(|i| o[i] as f64 + u * d[i] as f64);
            let m = point(q);
            // Along the NDC ray: m − ro parallel to rd, at a positive distance.
            let s = (m[2] - ro[2]) / rd[2];
            assert!(s > 0.0);
            for i in 0..3 {
                assert!((ro[i] + s * rd[i] - m[i]).abs() < 1e-5, "u {u} axis {i}");
            }
        }
        // The origin is where the ray crosses depth n.
        let t = (-(P.near as f64) - o[2] as f64) / d[2] as f64;
        let on_near: [f64; 3] = std::array::from_fn(|i| o[i] as f64 + t * d[i] as f64);
        let m = point(on_near);
        for i in 0..3 {
            assert!((m[i] - ro[i]).abs() < 1e-6);
        }
    }

    #[test]
    fn a_ray_not_heading_into_the_scene_misses() {
        for d in [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 0.0, f32::NAN]] {
            assert_eq!(ndc_ray([0.0; 3], d, P), MISSED_RAY);
        }
    }
}
