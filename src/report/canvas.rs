//! An RGB drawing surface over `image::RgbImage`: clipped pixels, rectangles, lines, text in the
//! built-in bitmap font, pasted images, and PNG output.

use super::font::{glyph, GLYPH_H, GLYPH_W};
use anyhow::{Context, Result};
use image::{Rgb, RgbImage};
use std::path::Path;

/// An RGB colour.
pub type Colour = [u8; 3];

pub const WHITE: Colour = [255, 255, 255];
pub const BLACK: Colour = [0, 0, 0];
pub const GREY: Colour = [150, 150, 150];
pub const LIGHT_GREY: Colour = [225, 225, 225];

/// A drawing surface; every drawing call clips to the image.
pub struct Canvas {
    pub img: RgbImage,
}

impl Canvas {
    /// A `w`×`h` canvas filled with `bg`.
    pub fn new(w: u32, h: u32, bg: Colour) -> Canvas {
        Canvas {
            img: RgbImage::from_pixel(w, h, Rgb(bg)),
        }
    }

    pub fn width(&self) -> i64 {
        self.img.width() as i64
    }

    pub fn height(&self) -> i64 {
        self.img.height() as i64
    }

    /// Set one pixel (ignored outside the canvas).
    pub fn set(&mut self, x: i64, y: i64, c: Colour) {
        if x >= 0 && y >= 0 && x < self.width() && y < self.height() {
            self.img.put_pixel(x as u32, y as u32, Rgb(c));
        }
    }

    /// Fill the rectangle with top-left corner (x, y) and size w×h.
    pub fn fill_rect(&mut self, x: i64, y: i64, w: i64, h: i64, c: Colour) {
        for yy in y.max(0)..(y + h).min(self.height()) {
            for xx in x.max(0)..(x + w).min(self.width()) {
                self.img.put_pixel(xx as u32, yy as u32, Rgb(c));
            }
        }
    }

    /// Outline of a rectangle.
    pub fn rect(&mut self, x: i64, y: i64, w: i64, h: i64, c: Colour) {
        self.fill_rect(x, y, w, 1, c);
        self.fill_rect(x, y + h - 1, w, 1, c);
        self.fill_rect(x, y, 1, h, c);
        self.fill_rect(x + w - 1, y, 1, h, c);
    }

    /// A line of the given width (pixels) from (x0, y0) to (x1, y1), sampled at unit steps along
    /// its longer axis. Non-finite endpoints draw nothing.
    pub fn line(&mut self, x0: f64, y0: f64, x1: f64, y1: f64, width: i64, c: Colour) {
        if ![x0, y0, x1, y1].iter().all(|v| v.is_finite()) {
            return;
        }
        // Keep far-off endpoints from making the loop huge (they are clipped anyway).
        let lim = 4.0 * (self.width() + self.height()) as f64;
        let (x0, y0, x1, y1) = (
            x0.clamp(-lim, lim),
            y0.clamp(-lim, lim),
            x1.clamp(-lim, lim),
            y1.clamp(-lim, lim),
        );
        let n = (x1 - x0).abs().max((y1 - y0).abs()).ceil().max(1.0) as i64;
        let off = (width - 1) / 2;
        for i in 0..=n {
            let t = i as f64 / n as f64;
            let x = (x0 + (x1 - x0) * t).round() as i64 - off;
            let y = (y0 + (y1 - y0) * t).round() as i64 - off;
            self.fill_rect(x, y, width, width, c);
        }
    }

    /// Width in pixels of `s` drawn at `scale`.
    pub fn text_width(s: &str, scale: u32) -> i64 {
        let n = s.chars().count() as i64;
        (n * (GLYPH_W as i64 + 1) - 1).max(0) * scale as i64
    }

    /// Height in pixels of a line of text at `scale`.
    pub fn text_height(scale: u32) -> i64 {
        (GLYPH_H * scale) as i64
    }

    /// Draw `s` with its top-left corner at (x, y), each font pixel a `scale`×`scale` square.
    pub fn text(&mut self, x: i64, y: i64, s: &str, scale: u32, c: Colour) {
        let sc = scale as i64;
        for (i, ch) in s.chars().enumerate() {
            let gx = x + i as i64 * (GLYPH_W as i64 + 1) * sc;
            for (row, bits) in glyph(ch).iter().enumerate() {
                for col in 0..GLYPH_W {
                    if bits & (1 << (GLYPH_W - 1 - col)) != 0 {
                        self.fill_rect(gx + col as i64 * sc, y + row as i64 * sc, sc, sc, c);
                    }
                }
            }
        }
    }

    /// Draw `s` centred horizontally on `cx`.
    pub fn text_centred(&mut self, cx: i64, y: i64, s: &str, scale: u32, c: Colour) {
        self.text(cx - Self::text_width(s, scale) / 2, y, s, scale, c);
    }

    /// Draw `s` rotated 90° counter-clockwise (reading bottom to top), centred vertically on `cy`,
    /// with its left edge (the glyph tops) at x.
    pub fn text_vertical(&mut self, x: i64, cy: i64, s: &str, scale: u32, c: Colour) {
        let sc = scale as i64;
        let y_start = cy + Self::text_width(s, scale) / 2;
        for (i, ch) in s.chars().enumerate() {
            let gy = y_start - i as i64 * (GLYPH_W as i64 + 1) * sc;
            for (row, bits) in glyph(ch).iter().enumerate() {
                for col in 0..GLYPH_W {
                    if bits & (1 << (GLYPH_W - 1 - col)) != 0 {
                        self.fill_rect(x + row as i64 * sc, gy - (col as i64 + 1) * sc, sc, sc, c);
                    }
                }
            }
        }
    }

    /// Paste `img` with its top-left corner at (x, y).
    pub fn blit(&mut self, img: &RgbImage, x: i64, y: i64) {
        for (px, py, p) in img.enumerate_pixels() {
            self.set(x + px as i64, y + py as i64, p.0);
        }
    }

    /// Write the canvas as PNG (atomically).
    pub fn save(&self, path: &Path) -> Result<()> {
        crate::io::atomic::write_png(
            path,
            self.img.as_raw(),
            self.img.width(),
            self.img.height(),
            image::ExtendedColorType::Rgb8,
        )
    }
}

/// Load an image as RGB, compositing any alpha channel over white (the datasets' background).
pub fn load_rgb_on_white(path: &Path) -> Result<RgbImage> {
    let img = image::open(path)
        .with_context(|| format!("reading image {}", path.display()))?
        .to_rgba8();
    let mut out = RgbImage::new(img.width(), img.height());
    for (x, y, p) in img.enumerate_pixels() {
        let a = p.0[3] as f32 / 255.0;
        let c = |v: u8| (v as f32 * a + 255.0 * (1.0 - a)).round() as u8;
        out.put_pixel(x, y, Rgb([c(p.0[0]), c(p.0[1]), c(p.0[2])]));
    }
    Ok(out)
}

/// Images side by side with a caption above each, on a white strip; images of different sizes
/// are top-aligned.
pub fn side_by_side(images: &[(String, RgbImage)], scale: u32) -> Canvas {
    let gap = 8i64;
    let caption_h = Canvas::text_height(scale) + 8;
    let w: i64 =
        images.iter().map(|(_, i)| i.width() as i64).sum::<i64>() + gap * (images.len() as i64 + 1);
    let h = images
        .iter()
        .map(|(_, i)| i.height() as i64)
        .max()
        .unwrap_or(0)
        + caption_h
        + gap;
    let mut c = Canvas::new(w.max(1) as u32, h.max(1) as u32, WHITE);
    let mut x = gap;
    for (caption, img) in images {
        c.text_centred(x + img.width() as i64 / 2, 4, caption, scale, BLACK);
        c.blit(img, x, caption_h);
        let (w, h) = (img.width() as i64, img.height() as i64);
        c.rect(x - 1, caption_h - 1, w + 2, h + 2, LIGHT_GREY);
        x += img.width() as i64 + gap;
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drawing_clips_and_text_has_the_measured_width() {
        let mut c = Canvas::new(40, 20, WHITE);
        c.line(-100.0, 10.0, 100.0, 10.0, 1, BLACK);
        c.line(f64::NAN, 0.0, 5.0, 5.0, 3, BLACK); // ignored
        c.fill_rect(-5, -5, 3, 3, BLACK); // fully outside
        for x in 0..40 {
            assert_eq!(c.img.get_pixel(x, 10).0, BLACK);
        }
        assert_eq!(c.img.get_pixel(0, 0).0, WHITE);

        let mut t = Canvas::new(60, 20, WHITE);
        t.text(1, 1, "E1.5E-2", 1, BLACK);
        let cols: Vec<u32> = (0..60)
            .filter(|&x| (0..20).any(|y| t.img.get_pixel(x, y).0 == BLACK))
            .collect();
        assert_eq!(*cols.first().unwrap(), 1);
        assert_eq!(
            *cols.last().unwrap() as i64,
            Canvas::text_width("E1.5E-2", 1)
        );
        assert_eq!(Canvas::text_width("ab", 2), 22);
    }

    #[test]
    fn vertical_text_is_the_transpose_of_horizontal_text() {
        let mut h = Canvas::new(30, 10, WHITE);
        h.text(0, 0, "AB", 1, BLACK);
        let mut v = Canvas::new(10, 30, WHITE);
        v.text_vertical(0, 15, "AB", 1, BLACK);
        let count = |c: &Canvas| c.img.pixels().filter(|p| p.0 == BLACK).count();
        assert_eq!(count(&h), count(&v));
        assert!(count(&h) > 10);
    }

    #[test]
    fn side_by_side_places_each_image() {
        let a = RgbImage::from_pixel(10, 10, Rgb([255, 0, 0]));
        let b = RgbImage::from_pixel(12, 8, Rgb([0, 0, 255]));
        let c = side_by_side(&[("A".into(), a), ("B".into(), b)], 1);
        assert_eq!(c.width(), 8 + 10 + 8 + 12 + 8);
        let top = Canvas::text_height(1) as u32 + 8;
        assert_eq!(c.img.get_pixel(8, top).0, [255, 0, 0]);
        assert_eq!(c.img.get_pixel(26, top).0, [0, 0, 255]);
    }
}
