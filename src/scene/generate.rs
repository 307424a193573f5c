//! Writes a built-in scene as a NeRF-synthetic dataset: `train|val|test/r_N.png` (RGBA, alpha =
//! coverage), `transforms_{train,val,test}.json` (camera_angle_x 0.6911112, cameras on a sphere
//! of radius 4 looking at the origin), `gt_points.ply` (area-uniform samples on every surface,
//! inner shells included, points buried inside other opaque solids dropped) and `scene.json`.
//! Deterministic for a seed.

use super::{build, render_view, Scene, SceneKind, SCENE_HALF_EXTENT};
use crate::data::{look_at, Camera};
use crate::run::replace::Replacement;
use anyhow::{bail, Context};
use glam::{DVec3, Mat4, Vec3};
use indicatif::{ProgressBar, ProgressStyle};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use rayon::prelude::*;
use serde_json::json;
use std::path::Path;
use std::time::Instant;

/// The field of view of every generated camera (NeRF-synthetic's).
pub const CAMERA_ANGLE_X: f32 = 0.6911112;
/// Distance of the cameras from the origin.
pub const CAMERA_RADIUS: f32 = 4.0;
/// Test cameras sit on a ring at this elevation (degrees).
pub const TEST_ELEVATION_DEG: f32 = 30.0;

/// Settings of [`generate`].
#[derive(Clone, Debug)]
pub struct GenerateOptions {
    /// Which scene.
    pub kind: SceneKind,
    /// Image width and height.
    pub res: u32,
    /// Training views; val gets max(1, views/10), test max(1, views/5).
    pub views: u32,
    /// Seed of the scene details, the cameras and the ground-truth samples.
    pub seed: u64,
    /// Samples per pixel along each axis (spp = spp_side²).
    pub spp_side: u32,
    /// Ground-truth sample spacing: sqrt(area per point), Blender units.
    pub gt_spacing: f64,
    /// Show a progress bar.
    pub progress: bool,
    /// Replace a scene that `make-scene` wrote before in the output folder (`--overwrite`).
    pub overwrite: bool,
}

impl GenerateOptions {
    /// Defaults for a scene: 256², 100 views, seed 0, 16 spp, spacing 0.0019.
    pub fn new(kind: SceneKind) -> Self {
        GenerateOptions {
            kind,
            res: 256,
            views: 100,
            seed: 0,
            spp_side: 4,
            gt_spacing: 0.0019,
            progress: false,
            overwrite: false,
        }
    }

    /// Views per split: (train, val, test).
    pub fn split_views(&self) -> [(&'static str, u32); 3] {
        [
            ("train", self.views),
            ("val", (self.views / 10).max(1)),
            ("test", (self.views / 5).max(1)),
        ]
    }
}

/// What generation produced and cost.
#[derive(Clone, Debug)]
pub struct GenerateReport {
    /// Views rendered.
    pub views: usize,
    /// Ground-truth points written.
    pub gt_points: usize,
    /// Seconds spent rendering.
    pub render_s: f64,
    /// Seconds spent sampling and writing ground truth.
    pub gt_s: f64,
    /// Total seconds.
    pub total_s: f64,
}

fn stream(seed: u64, purpose: u64) -> Pcg64 {
    Pcg64::seed_from_u64(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ purpose)
}

/// Camera-to-world matrices of one split. Train and val: uniform by area over the band of
/// elevations [−15°, 75°]; test: a ring at 30°.
pub fn split_cameras(split: &str, n: u32, seed: u64) -> Vec<Mat4> {
    let mut rng = stream(seed, if split == "train" { 1 } else { 2 });
    (0..n)
        .map(|i| {
            let (az, el) = if split == "test" {
                (
                    std::f32::consts::TAU * i as f32 / n as f32,
                    TEST_ELEVATION_DEG.to_radians(),
                )
            } else {
                let (s0, s1) = ((-15f32).to_radians().sin(), 75f32.to_radians().sin());
                let az = std::f32::consts::TAU * rng.random::<f32>();
                (az, (s0 + (s1 - s0) * rng.random::<f32>()).asin())
            };
            let eye = CAMERA_RADIUS * Vec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
            look_at(eye, Vec3::ZERO, Vec3::Z)
        })
        .collect()
}

/// The most samples per pixel along each axis `--spp` may ask for.
pub const MAX_SPP_SIDE: u32 = 32;

/// `scene.json`'s "generator": marks a folder as a built-in scene that may be regenerated.
const GENERATOR: &str = "alphasurf make-scene";

/// Generates the dataset into `out` (created if needed). It is built beside `out` and swapped in
/// when complete ([`crate::run::replace`]): a failure or a kill leaves `out` as it was.
pub fn generate(target: &Path, opts: &GenerateOptions) -> anyhow::Result<GenerateReport> {
    let t0 = Instant::now();
    if opts.res == 0 || opts.views == 0 || opts.spp_side == 0 {
        bail!("--res, --views and --spp must be positive");
    }
    if opts.spp_side > MAX_SPP_SIDE {
        bail!(
            "--spp {}: at most {MAX_SPP_SIDE} samples per pixel along each axis ({} per pixel); \
             more changes no pixel's 8-bit value and multiplies the render time",
            opts.spp_side,
            MAX_SPP_SIDE * MAX_SPP_SIDE
        );
    }
    if !(opts.gt_spacing > 0.0 && opts.gt_spacing.is_finite()) {
        bail!("--gt-spacing must be positive");
    }
    let scene = build(opts.kind, opts.seed);
    let (lo, hi) = scene.aabb();
    if lo.min_element() < -SCENE_HALF_EXTENT || hi.max_element() > SCENE_HALF_EXTENT {
        bail!(
            "scene '{}' does not fit in [-1.5, 1.5]^3: bounds {lo} .. {hi}",
            scene.name
        );
    }
    check_memory(&scene, opts)?;
    check_scene_folder(target, opts.overwrite)?;
    let staged = Replacement::begin(target, is_scene_entry)?;
    let out = staged.path();
    let splits = opts.split_views();
    let total_views: u64 = splits.iter().map(|s| s.1 as u64).sum();
    let bar = if opts.progress {
        let b = ProgressBar::new(total_views);
        b.set_style(
            ProgressStyle::with_template(
                "rendering {bar:40} {pos}/{len} views [{elapsed_precise} < {eta_precise}]",
            )
            .expect("static template"),
        );
        b
    } else {
        ProgressBar::hidden()
    };
    for (split, n) in splits {
        let dir = out.join(split);
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("{}: cannot create directory", dir.display()))?;
        let mut frames = Vec::new();
        for (i, c2w) in split_cameras(split, n, opts.seed).into_iter().enumerate() {
            let cam = Camera::from_angle_x(c2w, opts.res, opts.res, CAMERA_ANGLE_X);
            let rgba = render_view(&scene, &cam, opts.spp_side);
            let path = dir.join(format!("r_{i}.png"));
            crate::io::atomic::write_png(
                &path,
                &rgba,
                opts.res,
                opts.res,
                image::ExtendedColorType::Rgba8,
            )?;
            let rows: Vec<[f32; 4]> = (0..4).map(|r| c2w.row(r).to_array()).collect();
            frames.push(json!({"file_path": format!("./{split}/r_{i}"), "transform_matrix": rows}));
            bar.inc(1);
        }
        let path = out.join(format!("transforms_{split}.json"));
        let text = serde_json::to_string_pretty(
            &json!({"camera_angle_x": CAMERA_ANGLE_X, "frames": frames}),
        )?;
        crate::io::atomic::write_bytes(&path, text.as_bytes())?;
    }
    bar.finish_and_clear();
    let render_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let (points, ranges) = sample_gt(&scene, opts.gt_spacing, opts.seed);
    let ply = out.join("gt_points.ply");
    crate::io::write_points(&ply, &points)?;
    let gt_s = t1.elapsed().as_secs_f64();
    let report = GenerateReport {
        views: total_views as usize,
        gt_points: points.len(),
        render_s,
        gt_s,
        total_s: t0.elapsed().as_secs_f64(),
    };
    write_scene_json(out, &scene, opts, &ranges, points.len(), &report)?;
    staged.commit()?;
    Ok(report)
}

/// Bytes held per pixel of the view being rendered: the RGBA image, its encoded copy and the
/// per-tile candidate lists, rounded up.
const BYTES_PER_PIXEL: f64 = 16.0;
/// Bytes held per view until the end: its camera and its `transforms_*.json` entry.
const BYTES_PER_VIEW: f64 = 512.0;
/// Bytes per ground-truth point: the per-object list and the concatenated one (12 B each).
const BYTES_PER_GT_POINT: f64 = 24.0;

/// Refuse sizes that cannot be encoded (a PNG row count times width in 32 bits) or that need
/// more memory than is available: `--res`, `--views` and `--gt-spacing` are checked before
/// anything is rendered.
fn check_memory(scene: &Scene, opts: &GenerateOptions) -> anyhow::Result<()> {
    let px = opts.res as f64 * opts.res as f64;
    if px * 4.0 > u32::MAX as f64 {
        bail!(
            "--res {}: at most 32767 pixels a side (an RGBA image must stay under 4 GiB)",
            opts.res
        );
    }
    let views: f64 = opts.split_views().iter().map(|s| s.1 as f64).sum();
    let gt_points: f64 = scene
        .objects
        .iter()
        .map(|o| (o.shape.area() / (opts.gt_spacing * opts.gt_spacing)).ceil())
        .sum();
    let need = px * BYTES_PER_PIXEL + views * BYTES_PER_VIEW + gt_points * BYTES_PER_GT_POINT;
    crate::run::memory::ensure_fits(
        &format!(
            "make-scene --res {} --views {} --gt-spacing {} ({gt_points:.3e} ground-truth points)",
            opts.res, opts.views, opts.gt_spacing
        ),
        need,
    )
}

/// Area-uniform samples on every object: ceil(area/spacing²) per object, minus those strictly
/// inside another opaque closed solid. Returns the points and per object (start, count).
pub fn sample_gt(scene: &Scene, spacing: f64, seed: u64) -> (Vec<[f32; 3]>, Vec<(usize, usize)>) {
    let per: Vec<Vec<[f32; 3]>> = scene
        .objects
        .par_iter()
        .enumerate()
        .map(|(i, ob)| {
            let mut rng = stream(seed, 1000 + i as u64);
            let n = (ob.shape.area() / (spacing * spacing)).ceil() as usize;
            let blockers: Vec<_> = scene
                .objects
                .iter()
                .enumerate()
                .filter(|(j, o)| *j != i && o.opaque() && o.shape.is_closed())
                .map(|(_, o)| (o.shape.aabb(), &o.shape))
                .collect();
            let mut pts = Vec::with_capacity(n);
            for _ in 0..n {
                let p: DVec3 = ob.shape.sample(&mut rng);
                let buried = blockers
                    .iter()
                    .any(|((lo, hi), s)| p.cmpge(*lo).all() && p.cmple(*hi).all() && s.contains(p));
                if !buried {
                    pts.push(p.as_vec3().to_array());
                }
            }
            pts
        })
        .collect();
    let mut ranges = Vec::new();
    let mut all = Vec::with_capacity(per.iter().map(Vec::len).sum());
    for p in per {
        ranges.push((all.len(), p.len()));
        all.extend(p);
    }
    (all, ranges)
}

/// The entries (directly in the scene folder) that a generated scene consists of; anything else a
/// user put beside them is kept when the scene is replaced.
fn is_scene_entry(name: &str) -> bool {
    [
        "train",
        "val",
        "test",
        "transforms_train.json",
        "transforms_val.json",
        "transforms_test.json",
        "gt_points.ply",
        "scene.json",
    ]
    .contains(&name)
}

/// `out` must be new, empty, or (with `overwrite`) a scene this command wrote before (its
/// `scene.json` names the generator): files of anything else (a real dataset, a run) are never
/// replaced.
fn check_scene_folder(out: &Path, overwrite: bool) -> anyhow::Result<()> {
    if !out.exists() {
        return Ok(());
    }
    if !out.is_dir() {
        bail!("{}: exists and is not a directory", out.display());
    }
    let mut entries = std::fs::read_dir(out)
        .with_context(|| format!("{}: cannot list directory", out.display()))?;
    if entries.next().is_none() {
        return Ok(());
    }
    let generator = std::fs::read(out.join("scene.json"))
        .ok()
        .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
        .and_then(|v| v.get("generator")?.as_str().map(str::to_owned));
    if generator.as_deref() != Some(GENERATOR) {
        bail!(
            "{}: not empty and not a scene written by make-scene (no scene.json of ours); \
             its files would be replaced — give a new or empty --out (what an interrupted \
             make-scene of an earlier version left is removed with rm -r {})",
            out.display(),
            out.display()
        );
    }
    if !overwrite {
        bail!(
            "--out {} already holds a scene written by make-scene; pass --overwrite to replace it",
            out.display()
        );
    }
    Ok(())
}

fn write_scene_json(
    out: &Path,
    scene: &Scene,
    opts: &GenerateOptions,
    ranges: &[(usize, usize)],
    n_points: usize,
    report: &GenerateReport,
) -> anyhow::Result<()> {
    let v = |p: DVec3| json!([p.x, p.y, p.z]);
    let (lo, hi) = scene.aabb();
    let objects: Vec<_> = scene
        .objects
        .iter()
        .zip(ranges)
        .map(|(o, &(start, count))| {
            let (a, b) = o.shape.aabb();
            json!({
                "name": o.name,
                "kind": if o.opaque() { "opaque" } else { "translucent" },
                "thin": o.thin,
                "shape": o.shape.describe(),
                "material": o.material.describe(),
                "area": o.shape.area(),
                "bbox_min": v(a), "bbox_max": v(b),
                "point_start": start, "point_count": count,
            })
        })
        .collect();
    let area = scene.area();
    let doc = json!({
        "name": scene.name,
        "generator": GENERATOR,
        "seed": opts.seed,
        "bbox_min": v(lo), "bbox_max": v(hi),
        "objects": objects,
        "gt": {
            "file": "gt_points.ply",
            "n_points": n_points,
            "surface_area": area,
            "spacing": opts.gt_spacing,
            "sqrt_area_per_point": (area / n_points.max(1) as f64).sqrt(),
            "note": "area-uniform samples on every surface (inner shells included); samples strictly inside another opaque solid are dropped",
        },
        "render": {
            "engine": "alphasurf exact CPU ray caster (analytic intersections, alpha compositing of every crossing in depth order, no refraction)",
            "resolution": [opts.res, opts.res],
            "spp": opts.spp_side * opts.spp_side,
            "camera_angle_x": CAMERA_ANGLE_X,
            "camera_radius": CAMERA_RADIUS,
            "views": {"train": opts.split_views()[0].1, "val": opts.split_views()[1].1, "test": opts.split_views()[2].1},
            "light_dir": v(scene.light),
            "shading": format!("albedo*({}+{}*max(0,n.l)), double-sided", super::material::AMBIENT, super::material::DIFFUSE),
        },
        "alpha_semantics": "alpha = opacity of one surface layer; every crossing of a surface is composited; PNG alpha = pixel coverage",
        "timing_s": {"render": report.render_s, "gt": report.gt_s},
    });
    let path = out.join("scene.json");
    crate::io::atomic::write_json(&path, &doc)
}
