//! Orthographic views of point clouds coloured by a per-point value (e.g. the distance of each
//! predicted point to the ground truth). Points are drawn far to near as small squares, so the
//! nearest point shows at each pixel.

use super::canvas::{Canvas, Colour, WHITE};
use super::colormap::{colour_bar, scaled};
use image::RgbImage;

/// An orthographic camera looking at the origin from azimuth/elevation (degrees; z up, azimuth
/// from +x towards +y), fitted to a cloud so that its projection fills a `w`×`h` image.
#[derive(Clone, Copy, Debug)]
pub struct Projection {
    right: [f64; 3],
    up: [f64; 3],
    towards_eye: [f64; 3],
    centre: (f64, f64),
    pixels_per_unit: f64,
    w: u32,
    h: u32,
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

impl Projection {
    /// Fit the view to `points` (their projected bounding box, with a 5 % margin).
    pub fn fit(points: &[[f32; 3]], azimuth_deg: f64, elevation_deg: f64, w: u32, h: u32) -> Self {
        let (az, el) = (azimuth_deg.to_radians(), elevation_deg.to_radians());
        let towards_eye = [el.cos() * az.cos(), el.cos() * az.sin(), el.sin()];
        let right = [-az.sin(), az.cos(), 0.0];
        // up = towards_eye × right
        let up = [
            towards_eye[1] * right[2] - towards_eye[2] * right[1],
            towards_eye[2] * right[0] - towards_eye[0] * right[2],
            towards_eye[0] * right[1] - towards_eye[1] * right[0],
        ];
        let mut p = Projection {
            right,
            up,
            towards_eye,
            centre: (0.0, 0.0),
            pixels_per_unit: 1.0,
            w,
            h,
        };
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for q in points {
            let q = q.map(f64::from);
            let (x, y) = (dot(q, right), dot(q, up));
            if x.is_finite() && y.is_finite() {
                lo = [lo[0].min(x), lo[1].min(y)];
                hi = [hi[0].max(x), hi[1].max(y)];
            }
        }
        if lo[0].is_finite() {
            p.centre = ((lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0);
            let span = ((hi[0] - lo[0]) / w as f64).max((hi[1] - lo[1]) / h as f64);
            p.pixels_per_unit = if span > 0.0 { 0.95 / span } else { 1.0 };
        }
        p
    }

    /// Image width and height in pixels.
    pub fn size(&self) -> (u32, u32) {
        (self.w, self.h)
    }

    /// Unit vectors of the view: image right, image up, towards the eye.
    pub fn axes(&self) -> [[f64; 3]; 3] {
        [self.right, self.up, self.towards_eye]
    }

    /// Pixel position and depth (larger = nearer the eye) of a point.
    pub fn project(&self, q: [f32; 3]) -> (f64, f64, f64) {
        let q = q.map(f64::from);
        let x = (dot(q, self.right) - self.centre.0) * self.pixels_per_unit + self.w as f64 / 2.0;
        let y = self.h as f64 / 2.0 - (dot(q, self.up) - self.centre.1) * self.pixels_per_unit;
        (x, y, dot(q, self.towards_eye))
    }
}

/// Draw `points` as `size`-pixel squares on white, far to near, point i in `colour_of(i, t)`
/// where t ∈ [0, 1] is its depth (0 = farthest point, 1 = nearest).
pub fn render(
    points: &[[f32; 3]],
    proj: &Projection,
    size: u32,
    colour_of: impl Fn(usize, f64) -> Colour,
) -> RgbImage {
    let mut c = Canvas::new(proj.w, proj.h, WHITE);
    let mut order: Vec<(f64, f64, f64, usize)> = points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let (x, y, d) = proj.project(*p);
            (x, y, d, i)
        })
        .filter(|(x, y, d, _)| x.is_finite() && y.is_finite() && d.is_finite())
        .collect();
    order.sort_by(|a, b| a.2.total_cmp(&b.2));
    let (near, far) = (
        order.last().map_or(0.0, |o| o.2),
        order.first().map_or(0.0, |o| o.2),
    );
    let s = size.max(1) as i64;
    for (x, y, d, i) in order {
        let t = if near > far {
            (d - far) / (near - far)
        } else {
            1.0
        };
        let col = colour_of(i, t);
        c.fill_rect(
            x.round() as i64 - s / 2,
            y.round() as i64 - s / 2,
            s,
            s,
            col,
        );
    }
    c.img
}

/// One panel of [`error_figure`]: a title, the points, and a value per point (coloured on the
/// shared scale) or `None` (drawn in greys by depth, near = dark, e.g. the ground truth).
pub type Panel<'a> = (String, &'a [[f32; 3]], Option<&'a [f64]>);

/// Colour of point `i` (depth `t`, 1 = nearest) in a panel.
fn panel_colour(values: Option<&[f64]>, vmax: f64, i: usize, t: f64) -> Colour {
    match values {
        Some(v) => scaled(v.get(i).copied().unwrap_or(f64::NAN), 0.0, vmax),
        None => [(190.0 - 150.0 * t.clamp(0.0, 1.0)).round() as u8; 3],
    }
}

/// Panels of clouds side by side (one view, fitted to `frame_points`, e.g. the ground truth)
/// with a shared colour bar for [0, vmax] underneath, labelled `bar_title`.
pub fn error_figure(
    panels: &[Panel],
    frame_points: &[[f32; 3]],
    (azimuth, elevation): (f64, f64),
    panel_px: u32,
    vmax: f64,
    bar_title: &str,
) -> Canvas {
    let proj = Projection::fit(frame_points, azimuth, elevation, panel_px, panel_px);
    let images: Vec<(String, RgbImage)> = panels
        .iter()
        .map(|(t, p, v)| {
            let img = render(p, &proj, 2, |i, t| panel_colour(*v, vmax, i, t));
            (t.clone(), img)
        })
        .collect();
    let strip = super::canvas::side_by_side(&images, 2);
    let bar_h = 70i64;
    let mut c = Canvas::new(strip.img.width(), strip.img.height() + bar_h as u32, WHITE);
    c.blit(&strip.img, 0, 0);
    let w = (c.width() / 2).clamp(120, 600);
    let x = (c.width() - w) / 2 + Canvas::text_width(bar_title, 2) / 2;
    colour_bar(
        &mut c,
        x,
        strip.height() + 8,
        w,
        16,
        (0.0, vmax),
        5,
        bar_title,
        super::plot::fmt_tick,
        2,
    );
    c
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::colormap::turbo;

    #[test]
    fn projection_fits_and_orients() {
        // Looking from -y (azimuth -90°, elevation 0): +x is right, +z is up, -y is nearer.
        let pts = [[-1.0, 0.0, -1.0], [1.0, 0.0, 1.0]];
        let p = Projection::fit(&pts, -90.0, 0.0, 100, 100);
        let (x0, y0, _) = p.project([-1.0, 0.0, -1.0]);
        let (x1, y1, _) = p.project([1.0, 0.0, 1.0]);
        assert!(x0 < x1 && y0 > y1, "({x0},{y0}) ({x1},{y1})");
        assert!(x0 >= 0.0 && x1 < 100.0 && y1 >= 0.0 && y0 < 100.0);
        assert!((x1 - x0) > 90.0);
        let near = p.project([0.0, -1.0, 0.0]).2;
        let far = p.project([0.0, 1.0, 0.0]).2;
        assert!(near > far);
    }

    #[test]
    fn nearest_point_wins_and_colours_follow_values() {
        // Two points at the same pixel: the nearer one (y = -1, seen from -y) must show.
        let pts = [
            [0.0, 1.0, 0.0],
            [0.0, -1.0, 0.0],
            [1.0, 0.0, 1.0],
            [-1.0, 0.0, -1.0],
        ];
        let vals = [1.0, 0.0, 0.5, 0.5];
        let p = Projection::fit(&pts, -90.0, 0.0, 64, 64);
        let img = render(&pts, &p, 1, |i, _| scaled(vals[i], 0.0, 1.0));
        let (x, y, _) = p.project(pts[1]);
        assert_eq!(
            img.get_pixel(x.round() as u32, y.round() as u32).0,
            turbo(0.0)
        );
        assert_eq!(img.pixels().filter(|q| q.0 == turbo(0.5)).count(), 2);
        assert_eq!(img.pixels().filter(|q| q.0 == turbo(1.0)).count(), 0);
        // Depth shading: the nearest point gets t = 1, the farthest t = 0.
        let depth = render(&pts, &p, 1, |_, t| [(t * 255.0).round() as u8; 3]);
        let (x, y, _) = p.project(pts[1]);
        assert_eq!(
            depth.get_pixel(x.round() as u32, y.round() as u32).0,
            [255; 3]
        );
        assert_eq!(panel_colour(None, 1.0, 0, 1.0), [40; 3]);
        assert_eq!(panel_colour(Some(&[0.5]), 1.0, 0, 1.0), turbo(0.5));
    }

    #[test]
    fn error_figure_has_panels_and_a_bar() {
        let pts: Vec<[f32; 3]> = (0..500)
            .map(|i| {
                let t = i as f32 / 500.0 * std::f32::consts::TAU;
                [t.cos(), 0.0, t.sin()]
            })
            .collect();
        let vals: Vec<f64> = (0..500).map(|i| i as f64 / 25000.0).collect();
        let c = error_figure(
            &[("A".into(), &pts, None), ("B".into(), &pts, Some(&vals))],
            &pts,
            (-90.0, 0.0),
            120,
            0.02,
            "ERR",
        );
        assert!(c.width() > 240);
        let colours: std::collections::HashSet<[u8; 3]> = c.img.pixels().map(|p| p.0).collect();
        assert!(colours.len() > 50, "{} colours", colours.len());
    }
}
