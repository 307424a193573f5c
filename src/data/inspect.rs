//! `alphasurf inspect`: a summary of a loaded dataset — views per split and how they were split,
//! resolution, focal length, bounds of the camera centres, the foreground box found from the
//! cameras (captures without masks), object bounds estimated by carving a visual hull from the
//! training alpha masks, and warnings (no alpha channel, cameras not looking at the box, objects
//! reaching outside the box).

use super::background::BackgroundMode;
use super::camera::ray_box;
use super::dataset::Dataset;
use super::foreground::ForegroundBox;
use super::split::{Split, SplitRule};
use glam::{Mat4, Vec3, Vec4};
use rayon::prelude::*;
use std::fmt::Write as _;

/// Cells per axis of the carving grid over the scene box.
pub const HULL_RES: usize = 64;

/// Summary of one split.
#[derive(Clone, Debug)]
pub struct SplitSummary {
    /// Split name.
    pub name: String,
    /// Number of views.
    pub views: usize,
    /// Image size.
    pub width: u32,
    /// Image size.
    pub height: u32,
    /// Focal length (x, y) of the first view, pixels.
    pub focal: (f32, f32),
    /// Camera centres, min and max per axis (Blender units).
    pub centre_min: Vec3,
    /// See `centre_min`.
    pub centre_max: Vec3,
    /// Smallest and largest distance of a camera centre from the origin.
    pub distance: (f32, f32),
}

/// The result of [`inspect`].
#[derive(Clone, Debug)]
pub struct Inspection {
    /// Per split.
    pub splits: Vec<SplitSummary>,
    /// How the views were split.
    pub split_rule: SplitRule,
    /// The foreground box found from the cameras, and how (captures without masks).
    pub foreground: Option<ForegroundBox>,
    /// Whether the grid's box is the cube fitted to that foreground box (stage 1 then starts
    /// with every vertex of it allocated: `pipeline::train_plenoxels::initial_fill`).
    pub in_foreground_box: bool,
    /// Which space the grid lies in and why (`Dataset::space`).
    pub space: String,
    /// The background training composites on (`--background auto` resolved for the data).
    pub background: BackgroundMode,
    /// The scene box in Blender units (in NDC: the foreground box, or the NDC cube's bounds
    /// from the near plane to twice its depth, where the checks below look).
    pub box_min: Vec3,
    /// See `box_min`.
    pub box_max: Vec3,
    /// Visual-hull bounds of the object (Blender units), if the masks allow an estimate.
    pub object_bounds: Option<(Vec3, Vec3)>,
    /// Human-readable warnings.
    pub warnings: Vec<String>,
}

/// Summarises a dataset.
/// A warning when a split's images load smaller than their files by a factor that does not
/// divide the files' size: the box downscale dropped their ragged right and bottom edges.
fn cropped_by_downscale(s: &Split) -> Option<String> {
    let f = s.frames.first()?;
    let (fw, fh) = image::image_dimensions(&f.file).ok()?;
    let (w, h) = (f.image.width, f.image.height);
    (w > 0 && h > 0 && (fw % w != 0 || fh % h != 0)).then(|| {
        format!(
            "{}: the images ({fw}x{fh} in {}) load as {w}x{h}: the downscale factor does not \
             divide their size, so their right and bottom edges are dropped",
            s.name,
            f.file.display()
        )
    })
}

/// Advice for a capture trained in its foreground box without background spheres: nothing but
/// density inside the box can then hold the floor and walls its views see (measured on
/// `capture_birdcage`, docs/results.md).
fn room_advice(ds: &Dataset) -> Option<String> {
    let room = ds.foreground.as_ref()?.room?;
    let (lo, hi) = (room.lo(), room.hi());
    (ds.in_foreground_box() && !ds.background.spheres()).then(|| {
        format!(
            "the grid is the foreground box on --background {}: the floor and walls these views \
             see can only be density inside the box (capture_birdcage at 128³: Chamfer ×10⁻² \
             12.7 so, 3.9 in the room, 1.02 on spheres; docs/results.md). Leave --background \
             out (auto) or pass --background spheres to hold them on learned spheres around the \
             box, or train in the room: --box={:.2},{:.2},{:.2},{:.2},{:.2},{:.2}",
            ds.background.name(),
            lo.x,
            lo.y,
            lo.z,
            hi.x,
            hi.y,
            hi.z
        )
    })
}

pub fn inspect(ds: &Dataset) -> Inspection {
    let (box_min, box_max) = match (&ds.scene.ndc, &ds.foreground) {
        (None, _) => ds.scene.blender_bounds(),
        (Some(_), Some(fg)) => (fg.bounds.lo(), fg.bounds.hi()),
        (Some(ndc), None) => ndc.near_bounds(),
    };
    let mut warnings = Vec::new();
    let mut splits = Vec::new();
    for s in ds.splits() {
        splits.push(summarise(s));
        let no_alpha = s.frames.iter().filter(|f| !f.image.had_alpha).count();
        if no_alpha > 0 {
            warnings.push(format!(
                "{}: {no_alpha} of {} images have no alpha channel (no masks; treated as opaque)",
                s.name,
                s.frames.len()
            ));
        }
        warnings.extend(cropped_by_downscale(s));
        let outside: Vec<usize> = s
            .frames
            .iter()
            .enumerate()
            .filter(|(_, f)| {
                let c = &f.camera;
                !(0.0..=c.width as f32).contains(&c.cx) || !(0.0..=c.height as f32).contains(&c.cy)
            })
            .map(|(i, _)| i)
            .collect();
        if let Some(&i) = outside.first() {
            let c = &s.frames[i].camera;
            warnings.push(format!(
                "{}: {} views have their principal point outside the image (first: view {i}, \
                 cx {} cy {} in a {}x{} image): check the intrinsics",
                s.name,
                outside.len(),
                c.cx,
                c.cy,
                c.width,
                c.height
            ));
        }
        let off: Vec<usize> = s
            .frames
            .iter()
            .enumerate()
            .filter(|(_, f)| {
                let (o, d) = f.camera.ray_at(f.camera.cx, f.camera.cy);
                ray_box(o, d, box_min, box_max).is_none()
            })
            .map(|(i, _)| i)
            .collect();
        let mirrored: Vec<usize> = s
            .frames
            .iter()
            .enumerate()
            .filter(|(_, f)| glam::Mat3::from_mat4(f.camera.c2w).determinant() < 0.0)
            .map(|(i, _)| i)
            .collect();
        if !mirrored.is_empty() {
            warnings.push(format!(
                "{}: {} cameras are left-handed (rotation determinant < 0: a mirrored view), \
                 e.g. view {}",
                s.name,
                mirrored.len(),
                mirrored[0]
            ));
        }
        if !off.is_empty() {
            warnings.push(format!(
                "{}: {} cameras do not look at the scene box (their optical axis misses it), e.g. view {}",
                s.name,
                off.len(),
                off[0]
            ));
        }
    }
    warnings.extend(room_advice(ds));
    // `ds.splits()` lists the training split first.
    warnings.extend(no_parallax(&splits[0], box_max - box_min));
    // Without alpha or masks there is nothing to carve with (the warning above says so).
    let any_alpha = ds.train.frames.iter().any(|f| f.image.had_alpha);
    let object_bounds = any_alpha
        .then(|| visual_hull_bounds(&ds.train, box_min, box_max))
        .flatten();
    match object_bounds {
        None if !any_alpha => {}
        None => {
            warnings.push("no object bounds: the training masks carve away the whole box".into())
        }
        Some((lo, hi)) => {
            let cell = (box_max - box_min) / HULL_RES as f32;
            if lo.cmple(box_min + cell).any() || hi.cmpge(box_max - cell).any() {
                warnings.push(
                    "the estimated object reaches the scene box boundary: it may not fit in the grid (the layout's box is too small for it: check the scene's units; inspect --scale S shows the bounds at another scale)"
                        .into(),
                );
            }
        }
    }
    Inspection {
        splits,
        split_rule: ds.split_rule.clone(),
        foreground: ds.foreground.clone(),
        in_foreground_box: ds.in_foreground_box(),
        space: ds.space.clone(),
        background: ds.background,
        box_min,
        box_max,
        object_bounds,
        warnings,
    }
}

/// A warning when the training cameras (`s`, their split's summary) all stand at one point
/// (their centres span less than a thousandth of the scene box): views from one point have no
/// parallax, so no depth can be recovered from them (a pose export that repeated one pose, say).
fn no_parallax(s: &SplitSummary, box_size: Vec3) -> Option<String> {
    let span = (s.centre_max - s.centre_min).max_element();
    (s.views > 1 && span <= 1e-3 * box_size.max_element()).then(|| {
        format!(
            "{}: all {} camera centres lie within {span:.2e} of each other (the scene box is \
             {:.3} wide): views from one point have no parallax to recover depth from; check \
             the poses",
            s.name,
            s.views,
            box_size.max_element()
        )
    })
}

fn summarise(s: &Split) -> SplitSummary {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    let (mut dmin, mut dmax) = (f32::INFINITY, 0f32);
    for f in &s.frames {
        let c = f.camera.centre();
        lo = lo.min(c);
        hi = hi.max(c);
        dmin = dmin.min(c.length());
        dmax = dmax.max(c.length());
    }
    let c0 = &s.frames[0].camera;
    SplitSummary {
        name: s.name.clone(),
        views: s.frames.len(),
        width: s.width(),
        height: s.height(),
        focal: (c0.fx, c0.fy),
        centre_min: lo,
        centre_max: hi,
        distance: (dmin, dmax),
    }
}

/// Carves a `HULL_RES`³ grid over the box with the training masks (alpha > 0): a cell is removed
/// when some view sees no covered pixel in its projected footprint. Where a view's mask touches
/// the image border the object may extend outside that view, so there only footprints wholly
/// inside the image carve; elsewhere the part of the footprint inside the image decides (a cell
/// projecting outside the image is empty). The result is conservative (a superset of the
/// object's visual hull). Returns the bounds of the kept cells.
pub fn visual_hull_bounds(split: &Split, box_min: Vec3, box_max: Vec3) -> Option<(Vec3, Vec3)> {
    if split.frames.iter().all(|f| !f.image.had_alpha) {
        return None;
    }
    let n = HULL_RES;
    let cell = (box_max - box_min) / n as f32;
    let mut keep = vec![true; n * n * n];
    for f in &split.frames {
        let (w, h) = (f.image.width as usize, f.image.height as usize);
        // Summed-area table of the mask alpha > 0.
        let mut sat = vec![0u32; (w + 1) * (h + 1)];
        for y in 0..h {
            let mut row = 0u32;
            for x in 0..w {
                row += (f.image.data[4 * (y * w + x) + 3] > 0) as u32;
                sat[(y + 1) * (w + 1) + x + 1] = sat[y * (w + 1) + x + 1] + row;
            }
        }
        let touches_border = (0..w)
            .any(|x| pixel_covered(&sat, w, 0, x) || pixel_covered(&sat, w, h - 1, x))
            || (0..h).any(|y| pixel_covered(&sat, w, y, 0) || pixel_covered(&sat, w, y, w - 1));
        let cam = f.camera;
        let w2c: Mat4 = cam.c2w.inverse();
        keep.par_iter_mut().enumerate().for_each(|(i, k)| {
            if !*k {
                return;
            }
            let (ix, iy, iz) = (i % n, (i / n) % n, i / (n * n));
            let lo = box_min + cell * Vec3::new(ix as f32, iy as f32, iz as f32);
            let (mut x0, mut y0, mut x1, mut y1) = (f32::MAX, f32::MAX, f32::MIN, f32::MIN);
            for c in 0..8 {
                let p =
                    lo + cell * Vec3::new((c & 1) as f32, ((c >> 1) & 1) as f32, (c >> 2) as f32);
                let q = w2c * Vec4::new(p.x, p.y, p.z, 1.0);
                let depth = -q.z;
                if depth <= 1e-3 {
                    return;
                }
                let px = cam.cx + cam.fx * q.x / depth;
                let py = cam.cy - cam.fy * q.y / depth;
                x0 = x0.min(px);
                y0 = y0.min(py);
                x1 = x1.max(px);
                y1 = y1.max(py);
            }
            if touches_border && (x0 < 0.0 || y0 < 0.0 || x1 > w as f32 || y1 > h as f32) {
                return; // not wholly in view of a view the object may leave: cannot carve
            }
            let (a, b) = (
                (x0.floor().max(0.0) as usize).min(w),
                (y0.floor().max(0.0) as usize).min(h),
            );
            let (c, d) = (
                (x1.ceil().max(0.0) as usize).min(w),
                (y1.ceil().max(0.0) as usize).min(h),
            );
            let (c, d) = (c.max(a), d.max(b));
            let covered = sat[d * (w + 1) + c] + sat[b * (w + 1) + a]
                - sat[b * (w + 1) + c]
                - sat[d * (w + 1) + a];
            if covered == 0 {
                *k = false;
            }
        });
    }
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for (i, _) in keep.iter().enumerate().filter(|(_, k)| **k) {
        let idx = Vec3::new((i % n) as f32, ((i / n) % n) as f32, (i / (n * n)) as f32);
        lo = lo.min(box_min + cell * idx);
        hi = hi.max(box_min + cell * (idx + Vec3::ONE));
    }
    lo.x.is_finite().then_some((lo, hi))
}

/// Whether pixel (x, y) is covered, read from the summed-area table.
fn pixel_covered(sat: &[u32], w: usize, y: usize, x: usize) -> bool {
    let at = |yy: usize, xx: usize| sat[yy * (w + 1) + xx];
    at(y + 1, x + 1) + at(y, x) - at(y, x + 1) - at(y + 1, x) > 0
}

impl std::fmt::Display for Inspection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let v = |v: Vec3| format!("[{:.3}, {:.3}, {:.3}]", v.x, v.y, v.z);
        let mut s = String::new();
        for sp in &self.splits {
            let _ = writeln!(
                s,
                "{:<5} {:>4} views  {}x{}  focal {:.2}/{:.2} px  camera centres {} .. {}  distance {:.3}..{:.3}",
                sp.name,
                sp.views,
                sp.width,
                sp.height,
                sp.focal.0,
                sp.focal.1,
                v(sp.centre_min),
                v(sp.centre_max),
                sp.distance.0,
                sp.distance.1
            );
        }
        let _ = writeln!(s, "split: {}", self.split_rule);
        let _ = writeln!(s, "grid space: {}", self.space);
        let _ = writeln!(
            s,
            "background (--background auto): {}",
            self.background.name()
        );
        let _ = writeln!(
            s,
            "scene box (Blender units): {} .. {}",
            v(self.box_min),
            v(self.box_max)
        );
        if let Some(fg) = &self.foreground {
            let _ = writeln!(
                s,
                "foreground box (dataset units): {}\n  found from the cameras: {}",
                fg.bounds, fg.how
            );
            if self.in_foreground_box {
                let _ = writeln!(
                    s,
                    "  the grid is the cube around it: stage 1 starts with all of it allocated \
                     (the object's corners and what it stands on lie outside its inscribed sphere)"
                );
            }
        }
        match self.object_bounds {
            Some((lo, hi)) => {
                let _ = writeln!(
                    s,
                    "object bounds (visual hull, {HULL_RES}^3): {} .. {}",
                    v(lo),
                    v(hi)
                );
            }
            None => {
                let _ = writeln!(s, "object bounds: unknown");
            }
        }
        for w in &self.warnings {
            let _ = writeln!(s, "warning: {w}");
        }
        f.write_str(&s)
    }
}
