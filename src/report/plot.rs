//! x–y plots on a [`Canvas`]: linear or log₁₀ axes with "nice" ticks, line and marker series, a
//! title, axis labels and a legend. Non-finite points (and non-positive ones on a log axis) are
//! skipped; a line breaks there.

use super::canvas::{Canvas, Colour, BLACK, LIGHT_GREY, WHITE};

/// How a series is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Style {
    Line,
    Markers,
    LineMarkers,
}

/// One data series.
#[derive(Clone, Debug)]
pub struct Series {
    pub label: String,
    pub points: Vec<(f64, f64)>,
    pub colour: Colour,
    pub style: Style,
    /// Text drawn next to each marker (empty: none; else one per point).
    pub point_labels: Vec<String>,
}

/// One axis.
#[derive(Clone, Debug, Default)]
pub struct Axis {
    pub label: String,
    pub log: bool,
}

/// A plot panel's texts and axes.
#[derive(Clone, Debug, Default)]
pub struct Plot {
    pub title: String,
    pub x: Axis,
    pub y: Axis,
}

/// Series colours, distinguishable and readable on white.
pub const PALETTE: [Colour; 6] = [
    [31, 119, 180],
    [214, 39, 40],
    [44, 160, 44],
    [255, 127, 14],
    [148, 103, 189],
    [140, 86, 75],
];

/// "Nice" tick values covering [lo, hi]: about `n` multiples of 1, 2 or 5 × 10ᵏ.
pub fn nice_ticks(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    if !(lo.is_finite() && hi.is_finite()) || hi <= lo {
        return vec![lo];
    }
    let raw = (hi - lo) / n.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    (first..=last).map(|k| k as f64 * step).collect()
}

/// A compact label for a tick value: plain decimals for 0.001 ≤ |v| < 10⁵, else `1.5E-4` style.
pub fn fmt_tick(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    if (0.001..1e5).contains(&a) {
        let s = format!("{v:.6}");
        let s = s.trim_end_matches('0').trim_end_matches('.');
        s.to_string()
    } else {
        let s = format!("{v:.1E}");
        s.replace(".0E", "E")
    }
}

/// Axis transform: value → [0, 1] position, and the tick values.
struct Scale {
    lo: f64,
    hi: f64,
    log: bool,
}

impl Scale {
    fn fit(values: impl Iterator<Item = f64>, log: bool) -> Scale {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for v in values.filter(|v| v.is_finite() && (!log || *v > 0.0)) {
            let v = if log { v.log10() } else { v };
            lo = lo.min(v);
            hi = hi.max(v);
        }
        if !lo.is_finite() {
            (lo, hi) = (0.0, 1.0);
        }
        if hi - lo < 1e-12 * lo.abs().max(1.0) {
            let pad = if log { 0.5 } else { 0.5 * lo.abs().max(1.0) };
            (lo, hi) = (lo - pad, hi + pad);
        } else {
            let pad = 0.05 * (hi - lo);
            (lo, hi) = (lo - pad, hi + pad);
        }
        Scale { lo, hi, log }
    }

    fn pos(&self, v: f64) -> Option<f64> {
        if !v.is_finite() || (self.log && v <= 0.0) {
            return None;
        }
        let v = if self.log { v.log10() } else { v };
        Some((v - self.lo) / (self.hi - self.lo))
    }

    fn ticks(&self) -> Vec<f64> {
        if self.log {
            let (a, b) = (self.lo.ceil() as i64, self.hi.floor() as i64);
            let decades: Vec<f64> = (a..=b).map(|k| 10f64.powi(k as i32)).collect();
            if decades.len() >= 2 {
                return decades;
            }
            // Less than two decades in view: 1, 2, 5 × 10ᵏ.
            let mut t = Vec::new();
            for k in (self.lo.floor() as i64)..=(self.hi.ceil() as i64) {
                for m in [1.0, 2.0, 5.0] {
                    let v = m * 10f64.powi(k as i32);
                    if (self.lo..=self.hi).contains(&v.log10()) {
                        t.push(v);
                    }
                }
            }
            t
        } else {
            nice_ticks(self.lo, self.hi, 5)
        }
    }
}

/// Draw `plot` with `series` into the rectangle (x, y, w, h) of `c`.
pub fn draw(c: &mut Canvas, (x, y, w, h): (i64, i64, i64, i64), plot: &Plot, series: &[Series]) {
    let s = 2u32; // font scale
    let th = Canvas::text_height(s);
    let (left, right, top) = (18 + th + 6 * 12, 16, th + 16);
    let legend = legend_rows(series, w - left - right, s);
    let bottom =
        2 * th + 26 + legend.len() as i64 * (th + 8) + if legend.is_empty() { 0 } else { 6 };
    let (px, py, pw, ph) = (x + left, y + top, w - left - right, h - top - bottom);
    if pw < 10 || ph < 10 {
        return;
    }
    let all = || series.iter().flat_map(|s| s.points.iter());
    let sx = Scale::fit(all().map(|p| p.0), plot.x.log);
    let sy = Scale::fit(all().map(|p| p.1), plot.y.log);
    let to_px = |p: &(f64, f64)| -> Option<(f64, f64)> {
        Some((
            px as f64 + sx.pos(p.0)? * (pw - 1) as f64,
            (py + ph - 1) as f64 - sy.pos(p.1)? * (ph - 1) as f64,
        ))
    };
    c.fill_rect(px, py, pw, ph, WHITE);
    // Grid and ticks.
    for t in sx.ticks() {
        if let Some(u) = sx.pos(t) {
            let tx = px + (u * (pw - 1) as f64).round() as i64;
            c.fill_rect(tx, py, 1, ph, LIGHT_GREY);
            c.fill_rect(tx, py + ph, 1, 5, BLACK);
            c.text_centred(tx, py + ph + 8, &fmt_tick(t), s, BLACK);
        }
    }
    for t in sy.ticks() {
        if let Some(u) = sy.pos(t) {
            let ty = py + ph - 1 - (u * (ph - 1) as f64).round() as i64;
            c.fill_rect(px, ty, pw, 1, LIGHT_GREY);
            c.fill_rect(px - 5, ty, 5, 1, BLACK);
            let label = fmt_tick(t);
            c.text(
                px - 8 - Canvas::text_width(&label, s),
                ty - th / 2,
                &label,
                s,
                BLACK,
            );
        }
    }
    c.rect(px, py, pw, ph, BLACK);
    // Texts.
    c.text_centred(px + pw / 2, y + 6, &plot.title, s, BLACK);
    c.text_centred(px + pw / 2, py + ph + th + 20, &plot.x.label, s, BLACK);
    c.text_vertical(x + 6, py + ph / 2, &plot.y.label, s, BLACK);
    // Series, clipped to the plot area by drawing into a sub-canvas.
    let mut area = Canvas {
        img: image::imageops::crop_imm(&c.img, px as u32, py as u32, pw as u32, ph as u32)
            .to_image(),
    };
    for se in series {
        let pts: Vec<Option<(f64, f64)>> = se.points.iter().map(&to_px).collect();
        if se.style != Style::Markers {
            for pair in pts.windows(2) {
                if let (Some(a), Some(b)) = (pair[0], pair[1]) {
                    area.line(
                        a.0 - px as f64,
                        a.1 - py as f64,
                        b.0 - px as f64,
                        b.1 - py as f64,
                        2,
                        se.colour,
                    );
                }
            }
        }
        if se.style != Style::Line {
            for (i, p) in pts.iter().enumerate() {
                let Some(p) = p else { continue };
                let (mx, my) = (
                    (p.0 - px as f64).round() as i64,
                    (p.1 - py as f64).round() as i64,
                );
                area.fill_rect(mx - 4, my - 4, 9, 9, BLACK);
                area.fill_rect(mx - 3, my - 3, 7, 7, se.colour);
                if let Some(t) = se.point_labels.get(i) {
                    let tw = Canvas::text_width(t, 1);
                    // Right of the marker, or left of it near the right edge.
                    let tx = if mx + 8 + tw < pw {
                        mx + 8
                    } else {
                        mx - 8 - tw
                    };
                    area.text(tx, my - 3, t, 1, BLACK);
                }
            }
        }
    }
    c.blit(&area.img, px, py);
    c.rect(px, py, pw, ph, BLACK);
    // Legend, under the x-axis label (never over the data).
    for (i, row) in legend.iter().enumerate() {
        let yy = py + ph + 2 * th + 30 + i as i64 * (th + 8);
        let mut xx = px;
        for se in row {
            if se.style == Style::Markers {
                c.fill_rect(xx + 8, yy + th / 2 - 4, 9, 9, BLACK);
                c.fill_rect(xx + 9, yy + th / 2 - 3, 7, 7, se.colour);
            } else {
                c.fill_rect(xx + 2, yy + th / 2 - 1, 22, 3, se.colour);
            }
            c.text(xx + 30, yy, &se.label, s, BLACK);
            xx += legend_entry_width(se, s);
        }
    }
}

/// Width of one legend entry: swatch, label, gap.
fn legend_entry_width(se: &Series, scale: u32) -> i64 {
    30 + Canvas::text_width(&se.label, scale) + 24
}

/// The labelled series laid out in rows that fit `width`.
fn legend_rows(series: &[Series], width: i64, scale: u32) -> Vec<Vec<&Series>> {
    let mut rows: Vec<Vec<&Series>> = Vec::new();
    let mut used = 0;
    for se in series.iter().filter(|s| !s.label.is_empty()) {
        let w = legend_entry_width(se, scale);
        match rows.last_mut() {
            Some(r) if used + w <= width => r.push(se),
            _ => {
                rows.push(vec![se]);
                used = 0;
            }
        }
        used += w;
    }
    rows
}

/// One plot as its own `w`×`h` canvas.
pub fn single(w: u32, h: u32, plot: &Plot, series: &[Series]) -> Canvas {
    let mut c = Canvas::new(w, h, WHITE);
    draw(&mut c, (0, 0, w as i64, h as i64), plot, series);
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nice_ticks_are_round_and_cover_the_range() {
        assert_eq!(
            nice_ticks(0.0, 1.0, 5),
            vec![0.0, 0.2, 0.4, 0.6000000000000001, 0.8, 1.0]
        );
        let t = nice_ticks(13.0, 87.0, 5);
        assert_eq!(t, vec![20.0, 40.0, 60.0, 80.0]);
        assert_eq!(nice_ticks(3.0, 3.0, 5), vec![3.0]);
        assert_eq!(nice_ticks(f64::NAN, 1.0, 5).len(), 1);
    }

    #[test]
    fn tick_labels_are_compact() {
        assert_eq!(fmt_tick(0.0), "0");
        assert_eq!(fmt_tick(20.0), "20");
        assert_eq!(fmt_tick(0.25), "0.25");
        assert_eq!(fmt_tick(1e-3), "0.001");
        assert_eq!(fmt_tick(0.005), "0.005");
        assert_eq!(fmt_tick(1e-4), "1E-4");
        assert_eq!(fmt_tick(2.5e-4), "2.5E-4");
        assert_eq!(fmt_tick(1e6), "1E6");
    }

    #[test]
    fn log_scale_ticks_are_decades_or_1_2_5() {
        let s = Scale::fit([1e-4, 1e-1].into_iter(), true);
        assert_eq!(s.ticks(), vec![1e-4, 1e-3, 1e-2, 1e-1]);
        let s = Scale::fit([0.011, 0.08].into_iter(), true);
        let t = s.ticks();
        assert!(t.contains(&0.02) && t.contains(&0.05), "{t:?}");
        assert_eq!(s.pos(-1.0), None);
        assert_eq!(s.pos(f64::NAN), None);
    }

    #[test]
    fn series_are_drawn_in_their_colours_inside_the_frame() {
        let red = [214, 39, 40];
        let series = [
            Series {
                label: "A".into(),
                points: (0..50).map(|i| (i as f64, (i as f64).sin())).collect(),
                colour: red,
                style: Style::Line,
                point_labels: vec![],
            },
            Series {
                label: String::new(),
                points: vec![(10.0, f64::NAN), (f64::INFINITY, 0.0)],
                colour: [0, 0, 255],
                style: Style::Markers,
                point_labels: vec!["P".into()],
            },
        ];
        let plot = Plot {
            title: "T".into(),
            x: Axis {
                label: "X".into(),
                log: false,
            },
            y: Axis {
                label: "Y".into(),
                log: false,
            },
        };
        let c = single(400, 300, &plot, &series);
        let reds = c.img.pixels().filter(|p| p.0 == red).count();
        assert!(reds > 200, "only {reds} red pixels");
        assert!(
            !c.img.pixels().any(|p| p.0 == [0, 0, 255]),
            "non-finite point drawn"
        );
    }
}
