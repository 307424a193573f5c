//! A perceptual colour map for per-point values and its colour bar: a piecewise-linear
//! approximation of Google's Turbo (dark blue → cyan → green → yellow → red), readable on white.

use super::canvas::{Canvas, Colour, BLACK};

/// Turbo control points at t = 0, 1/8, …, 1.
const STOPS: [[f32; 3]; 9] = [
    [48.0, 18.0, 59.0],
    [65.0, 105.0, 225.0],
    [32.0, 175.0, 240.0],
    [40.0, 230.0, 170.0],
    [120.0, 254.0, 80.0],
    [200.0, 235.0, 40.0],
    [250.0, 170.0, 40.0],
    [225.0, 75.0, 15.0],
    [122.0, 4.0, 3.0],
];

/// Colour of `t` ∈ [0, 1] (clamped; NaN maps to 0).
pub fn turbo(t: f64) -> Colour {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) } as f32;
    let x = t * (STOPS.len() - 1) as f32;
    let i = (x.floor() as usize).min(STOPS.len() - 2);
    let f = x - i as f32;
    let (a, b) = (STOPS[i], STOPS[i + 1]);
    [0, 1, 2].map(|k| (a[k] + (b[k] - a[k]) * f).round() as u8)
}

/// Colour of `v` on the scale [lo, hi].
pub fn scaled(v: f64, lo: f64, hi: f64) -> Colour {
    turbo((v - lo) / (hi - lo).max(f64::MIN_POSITIVE))
}

/// A horizontal colour bar at (x, y) of size w×h with `ticks` labels below it: the values
/// lo + k·(hi − lo)/(ticks − 1), printed with `fmt`; `title` is drawn to the left of the bar.
#[allow(clippy::too_many_arguments)]
pub fn colour_bar(
    c: &mut Canvas,
    x: i64,
    y: i64,
    w: i64,
    h: i64,
    (lo, hi): (f64, f64),
    ticks: usize,
    title: &str,
    fmt: impl Fn(f64) -> String,
    scale: u32,
) {
    for i in 0..w {
        let col = turbo(i as f64 / (w - 1).max(1) as f64);
        c.fill_rect(x + i, y, 1, h, col);
    }
    c.rect(x - 1, y - 1, w + 2, h + 2, BLACK);
    let tw = Canvas::text_width(title, scale);
    c.text(
        x - tw - 8,
        y + (h - Canvas::text_height(scale)) / 2,
        title,
        scale,
        BLACK,
    );
    let ticks = ticks.max(2);
    for k in 0..ticks {
        let tx = x + (w - 1) * k as i64 / (ticks - 1) as i64;
        c.fill_rect(tx, y + h, 1, 4, BLACK);
        let v = lo + (hi - lo) * k as f64 / (ticks - 1) as f64;
        c.text_centred(tx, y + h + 6, &fmt(v), scale, BLACK);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn luma(c: Colour) -> f32 {
        0.299 * c[0] as f32 + 0.587 * c[1] as f32 + 0.114 * c[2] as f32
    }

    #[test]
    fn endpoints_clamping_and_continuity() {
        assert_eq!(turbo(0.0), [48, 18, 59]);
        assert_eq!(turbo(1.0), [122, 4, 3]);
        assert_eq!(turbo(-3.0), turbo(0.0));
        assert_eq!(turbo(7.0), turbo(1.0));
        assert_eq!(turbo(f64::NAN), turbo(0.0));
        assert_eq!(scaled(5.0, 0.0, 10.0), turbo(0.5));
        assert_eq!(scaled(1.0, 1.0, 1.0), turbo(0.0)); // degenerate range: no NaN, no panic
                                                       // Neighbouring values get neighbouring colours (no jumps).
        for i in 0..1000 {
            let (a, b) = (turbo(i as f64 / 1000.0), turbo((i + 1) as f64 / 1000.0));
            for k in 0..3 {
                assert!((a[k] as i32 - b[k] as i32).abs() <= 2, "jump at {i}");
            }
        }
        // Dark at both ends, bright in the middle, as Turbo.
        assert!(luma(turbo(0.5)) > 2.0 * luma(turbo(0.0)));
        assert!(luma(turbo(0.5)) > 2.0 * luma(turbo(1.0)));
    }

    #[test]
    fn colour_bar_draws_the_map_and_labels() {
        let mut c = Canvas::new(300, 60, [255; 3]);
        colour_bar(
            &mut c,
            80,
            10,
            200,
            12,
            (0.0, 2.0),
            3,
            "ERR",
            |v| format!("{v:.1}"),
            1,
        );
        assert_eq!(c.img.get_pixel(80, 15).0, turbo(0.0));
        assert_eq!(c.img.get_pixel(279, 15).0, turbo(1.0));
        // Tick labels under the bar.
        assert!((30..45).any(|y| (70..290).any(|x| c.img.get_pixel(x, y).0 == BLACK)));
    }
}
