//! A shaded orthographic view of a triangle mesh: each face is filled through a depth buffer and
//! lit by a light over the viewer's left shoulder (Lambert, both sides lit, so the winding does
//! not matter), grey on white.

use super::canvas::WHITE;
use super::cloud::Projection;
use image::{Rgb, RgbImage};

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Render `faces` over `positions` with `proj`.
pub fn render_mesh(positions: &[[f32; 3]], faces: &[[u32; 3]], proj: &Projection) -> RgbImage {
    let [right, up, eye] = proj.axes();
    let light = {
        let l: [f64; 3] = std::array::from_fn(|i| eye[i] + 0.5 * up[i] - 0.4 * right[i]);
        let n = dot(l, l).sqrt();
        l.map(|v| v / n)
    };
    let (w, h) = (proj.size().0 as usize, proj.size().1 as usize);
    let mut img = RgbImage::from_pixel(w as u32, h as u32, Rgb(WHITE));
    let mut depth = vec![f64::NEG_INFINITY; w * h];
    for f in faces {
        let p = f.map(|i| positions[i as usize].map(f64::from));
        let (u, v): ([f64; 3], [f64; 3]) = (
            std::array::from_fn(|k| p[1][k] - p[0][k]),
            std::array::from_fn(|k| p[2][k] - p[0][k]),
        );
        let n = [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ];
        let len = dot(n, n).sqrt();
        let has_area = len > 0.0;
        if !has_area {
            continue;
        }
        let shade = dot(n, light).abs() / len;
        let grey = (60.0 + 180.0 * shade).round().clamp(0.0, 255.0) as u8;
        let s = p.map(|q| proj.project(q.map(|x| x as f32)));
        let area = (s[1].0 - s[0].0) * (s[2].1 - s[0].1) - (s[2].0 - s[0].0) * (s[1].1 - s[0].1);
        let visible = area.abs() > 1e-12;
        if !visible {
            continue;
        }
        let x0 = s
            .iter()
            .map(|q| q.0)
            .fold(f64::INFINITY, f64::min)
            .floor()
            .max(0.0);
        let x1 = s
            .iter()
            .map(|q| q.0)
            .fold(f64::NEG_INFINITY, f64::max)
            .ceil()
            .min(w as f64 - 1.0);
        let y0 = s
            .iter()
            .map(|q| q.1)
            .fold(f64::INFINITY, f64::min)
            .floor()
            .max(0.0);
        let y1 = s
            .iter()
            .map(|q| q.1)
            .fold(f64::NEG_INFINITY, f64::max)
            .ceil()
            .min(h as f64 - 1.0);
        if !(x0 <= x1 && y0 <= y1) {
            continue;
        }
        for y in y0 as usize..=y1 as usize {
            for x in x0 as usize..=x1 as usize {
                // Barycentric coordinates of the pixel centre.
                let (px, py) = (x as f64, y as f64);
                let b1 =
                    ((px - s[0].0) * (s[2].1 - s[0].1) - (s[2].0 - s[0].0) * (py - s[0].1)) / area;
                let b2 =
                    ((s[1].0 - s[0].0) * (py - s[0].1) - (px - s[0].0) * (s[1].1 - s[0].1)) / area;
                let b0 = 1.0 - b1 - b2;
                if b0 < 0.0 || b1 < 0.0 || b2 < 0.0 {
                    continue;
                }
                let d = b0 * s[0].2 + b1 * s[1].2 + b2 * s[2].2;
                let k = y * w + x;
                if d > depth[k] {
                    depth[k] = d;
                    img.put_pixel(x as u32, y as u32, Rgb([grey; 3]));
                }
            }
        }
    }
    img
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearer_faces_hide_farther_ones_and_shading_follows_the_light() {
        // Two squares facing the viewer (from −y): a near one over x < 0 and a far one over the
        // whole width; then a square seen edge-on, which covers nothing.
        let pos = [
            [-1.0, -1.0, -1.0],
            [0.0, -1.0, -1.0],
            [0.0, -1.0, 1.0],
            [-1.0, -1.0, 1.0],
            [-1.0, 1.0, -1.0],
            [1.0, 1.0, -1.0],
            [1.0, 1.0, 1.0],
            [-1.0, 1.0, 1.0],
        ];
        let faces = [[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]];
        let proj = Projection::fit(&pos, -90.0, 0.0, 64, 64);
        let img = render_mesh(&pos, &faces, &proj);
        let near = img.get_pixel(16, 32).0;
        let far = img.get_pixel(48, 32).0;
        // Both squares face the same way: the same grey, not white; the near one in front.
        assert_ne!(near, WHITE);
        assert_eq!(near, far);
        let near_only = render_mesh(&pos, &faces[..2], &proj);
        assert_eq!(near_only.get_pixel(16, 32).0, near);
        assert_eq!(near_only.get_pixel(48, 32).0, WHITE);
        // A face turned away from the light is darker than one facing it.
        let tilted = [
            [0.0, -1.0, -1.0],
            [1.0, 0.0, -1.0],
            [1.0, 0.0, 1.0],
            [0.0, -1.0, 1.0],
        ];
        let t = render_mesh(&tilted, &[[0, 1, 2], [0, 2, 3]], &proj);
        let g = t
            .pixels()
            .find(|p| p.0 != WHITE)
            .expect("tilted face drawn")
            .0;
        assert!(g[0] < near[0], "{g:?} vs {near:?}");
    }
}
