//! The demo's `report.md`, `results.json` and PNG figures: a test view next to its renderings,
//! the point clouds coloured by their distance to the ground truth, the meshes shaded, the
//! training curves (from each run's `train_log.csv`), and Chamfer against the Plenoxels level.

use super::{objects_table, table, Row};
use crate::backend::Backend;
use crate::io::read_points;
use crate::math::knn::PointIndex;
use crate::mesh::ply::read_mesh_ply;
use crate::pipeline::extract::DEFAULT_RAYS_PER_AXIS;
use crate::pipeline::steps::TrainedRun;
use crate::report::canvas::{load_rgb_on_white, side_by_side, Canvas, WHITE};
use crate::report::cloud::{error_figure, Panel, Projection};
use crate::report::log;
use crate::report::mesh::render_mesh;
use crate::report::plot::{self, Axis, Plot, Series, Style, PALETTE};
use crate::scene::SceneKind;
use anyhow::{Context, Result};
use serde_json::json;
use std::path::{Path, PathBuf};

/// Upper end of the error colour scale, Blender units (twice the F-score threshold).
pub const ERROR_VMAX: f64 = 0.02;

/// View of the point-cloud figure: azimuth, elevation (degrees; the front, slightly from above).
pub const CLOUD_VIEW: (f64, f64) = (-65.0, 20.0);

/// What the report is made of.
pub struct Inputs<'a> {
    pub scene: SceneKind,
    pub out: &'a Path,
    pub data: &'a Path,
    pub s1: &'a TrainedRun,
    /// The stage-2 run, or why there is none.
    pub s2: Result<&'a TrainedRun, String>,
    pub rows: &'a [Row],
    pub fast: bool,
    pub backend: Backend,
    /// `extract --rays-per-axis` of every extraction.
    pub rays_per_axis: u32,
    /// `--grid-res`, when given.
    pub grid_res: Option<u32>,
    pub elapsed_s: f64,
}

/// A figure maker: writes the PNG at the path, returns the report section introducing it.
type Figure = fn(&Inputs, &Path) -> Result<String>;

/// Write the figures, `report.md` and `results.json`; returns the PNG paths.
pub fn write(r: &Inputs) -> Result<Vec<PathBuf>> {
    let mut md = String::new();
    let mut pngs = Vec::new();
    let cmd = format!(
        "alphasurf demo --scene {}{} --backend {}{}{}",
        r.scene.name(),
        if r.fast { " --fast" } else { "" },
        r.backend,
        r.grid_res
            .map_or(String::new(), |n| format!(" --grid-res {n}")),
        if r.rays_per_axis == DEFAULT_RAYS_PER_AXIS {
            String::new()
        } else {
            format!(" --rays-per-axis {}", r.rays_per_axis)
        }
    );
    md += &format!("# αSurf demo: the built-in `{}` scene\n\n", r.scene.name());
    md += &format!(
        "Made by `{cmd}` in {:.0} s (scene in `{}`, stage 1 in `{}`{}).\n\n",
        r.elapsed_s,
        rel(r.out, r.data),
        rel(r.out, &r.s1.dir),
        match &r.s2 {
            Ok(s2) => format!(", stage 2 in `{}`", rel(r.out, &s2.dir)),
            Err(_) => String::new(),
        }
    );
    md += "## Results\n\n";
    md += &table(r.rows, true);
    md += "\nChamfer: mean of the predicted→GT and GT→predicted nearest-point distances \
           (Blender units, distances ≥ 1.5 left out) × 100; F1 at 0.01 (`alphasurf eval`). \
           Test PSNR: mean over the test views of the run the points come from. Wall time: the \
           training command(s) that produced the points (stage 1; stage 1 + stage 2 for αSurf) \
           plus `alphasurf extract`.\n\n";
    md += &format!(
        "Backend `{}`, {} CPU threads; wall times include whatever else the machine was \
         running.\n\n",
        r.backend,
        std::thread::available_parallelism().map_or(0, |n| n.get())
    );
    let best = r.rows.iter().find(|x| x.kind == "plenoxels_best");
    let surf = r.rows.iter().find(|x| x.kind == "alphasurf");
    match (
        &r.s2,
        best.and_then(|b| b.chamfer_e2),
        surf.and_then(|s| s.chamfer_e2),
    ) {
        (Ok(_), Some(b), Some(a)) => {
            md += &format!(
                "αSurf's Chamfer is {:+.1} % relative to the best Plenoxels level set.\n\n",
                100.0 * (a - b) / b
            )
        }
        (Err(e), _, _) => {
            md += &format!(
                "**Stage 2 (αSurf) did not run**, so there is no αSurf row:\n\n```\n{}\n```\n\n",
                e.trim()
            )
        }
        _ => md += "αSurf's point cloud could not be evaluated (see the table).\n\n",
    }
    if let Some(t) = best.zip(surf).and_then(|(b, a)| objects_table(b, a, true)) {
        md += "### Where the Chamfer distance comes from\n\n";
        md += "Each object group's share of the Chamfer distance ×10⁻² (`alphasurf eval` splits \
               it over the scene's objects: a GT point counts for its object, a predicted point \
               for the object of its nearest GT point; the shares add up to the Chamfer \
               distance).\n\n";
        md += &t;
        md += "\n";
    }

    let figs: [(&str, Figure); 5] = [
        ("test_view.png", test_view),
        ("error_cloud.png", error_cloud),
        ("meshes.png", meshes),
        ("curves.png", curves),
        ("chamfer_levels.png", chamfer_levels),
    ];
    for (name, f) in figs {
        let path = r.out.join(name);
        match f(r, &path) {
            Ok(text) => {
                md += &text;
                md += &format!("\n![{name}]({name})\n\n");
                pngs.push(path);
            }
            Err(e) => {
                eprintln!("demo: figure {name}: {e:#}");
                md += &format!("Figure `{name}` could not be made: {e:#}\n\n");
            }
        }
    }
    let path = r.out.join("report.md");
    crate::io::atomic::write_bytes(&path, md.as_bytes())?;
    let results = json!({
        "command": cmd,
        "scene": r.scene.name(),
        "backend": r.backend,
        "rays_per_axis": r.rays_per_axis,
        "grid_res": r.grid_res,
        "elapsed_s": r.elapsed_s,
        "stage1": { "dir": r.s1.dir, "wall_s": r.s1.wall_s, "test_psnr": r.s1.test_psnr, "train_rays_per_s": r.s1.train_rays_per_s },
        "stage2": match &r.s2 {
            Ok(s) => json!({ "dir": s.dir, "wall_s": s.wall_s, "test_psnr": s.test_psnr, "train_rays_per_s": s.train_rays_per_s }),
            Err(e) => json!({ "error": e }),
        },
        "rows": r.rows,
        "figures": pngs,
    });
    let path = r.out.join("results.json");
    crate::io::atomic::write_json(&path, &results)?;
    Ok(pngs)
}

/// `p` relative to `base` when it is inside it.
fn rel(base: &Path, p: &Path) -> String {
    p.strip_prefix(base).unwrap_or(p).display().to_string()
}

/// The test images' paths (from transforms_test.json) in split order.
fn test_images(data: &Path) -> Result<Vec<PathBuf>> {
    let p = data.join("transforms_test.json");
    let v: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(&p).with_context(|| format!("reading {}", p.display()))?,
    )
    .with_context(|| format!("parsing {}", p.display()))?;
    let frames = v["frames"]
        .as_array()
        .with_context(|| format!("{}: no frames", p.display()))?;
    frames
        .iter()
        .map(|f| {
            let fp = f["file_path"]
                .as_str()
                .with_context(|| format!("{}: frame without file_path", p.display()))?;
            let mut path = data.join(fp.trim_start_matches("./"));
            if path.extension().is_none() {
                path.set_extension("png");
            }
            Ok(path)
        })
        .collect()
}

/// Index of the image with the most non-white pixels (the most object on screen).
pub fn most_covered(images: &[image::RgbImage]) -> usize {
    images
        .iter()
        .enumerate()
        .max_by_key(|(_, im)| im.pixels().filter(|p| p.0.iter().any(|&c| c < 250)).count())
        .map_or(0, |(i, _)| i)
}

/// Test view (the one showing the most object) next to stage 1's and stage 2's renderings.
fn test_view(r: &Inputs, path: &Path) -> Result<String> {
    let gts = test_images(r.data)?;
    let imgs: Vec<image::RgbImage> = gts
        .iter()
        .map(|p| load_rgb_on_white(p))
        .collect::<Result<_>>()?;
    let i = most_covered(&imgs);
    let mut panels = vec![("GROUND TRUTH".to_string(), imgs[i].clone())];
    let mut runs = vec![("PLENOXELS", r.s1)];
    if let Ok(s2) = &r.s2 {
        runs.push(("αSURF", s2));
    }
    for (name, run) in runs {
        let renders = run.dir.join(crate::run::dir::TEST_RENDERS);
        let img = load_rgb_on_white(&renders.join(format!("r_{i}.png")))?;
        let label = match run.test_psnr_per_view.get(i) {
            Some(p) => format!("{name} {p:.2} DB"),
            None => name.to_string(),
        };
        panels.push((label, img));
    }
    // Small images (test sizes) are enlarged with nearest-neighbour pixels so captions fit.
    let k = 256u32.div_ceil(imgs[i].width().max(1)).max(1);
    if k > 1 {
        for (_, im) in panels.iter_mut() {
            *im = image::imageops::resize(
                im,
                im.width() * k,
                im.height() * k,
                image::imageops::FilterType::Nearest,
            );
        }
    }
    side_by_side(&panels, 2).save(path)?;
    Ok(format!(
        "## Test view\n\nTest view {i} (the one showing the most of the object): ground truth, \
         then the renderings of stage 1 (Plenoxels){} with their PSNR.\n",
        if r.s2.is_ok() {
            " and stage 2 (αSurf)"
        } else {
            ""
        }
    ))
}

/// Ground truth, the best Plenoxels level and αSurf, the predictions coloured by the distance of
/// each point to the nearest ground-truth point.
fn error_cloud(r: &Inputs, path: &Path) -> Result<String> {
    let gt = read_points(&r.data.join("gt_points.ply"))?;
    let index = PointIndex::new(&gt)?;
    let mut clouds: Vec<(String, Vec<[f32; 3]>, Vec<f64>)> = Vec::new();
    for row in r
        .rows
        .iter()
        .filter(|x| (x.kind == "plenoxels_best" || x.kind == "alphasurf") && x.error.is_none())
    {
        let pts = read_points(&row.ply)?;
        let d = index.nearest_distances(&pts);
        let label = match row.level {
            Some(l) => format!("PLENOXELS σ = {l}"),
            None => "αSURF".to_string(),
        };
        clouds.push((format!("{label}: {} PTS", pts.len()), pts, d));
    }
    anyhow::ensure!(!clouds.is_empty(), "no evaluated point cloud to show");
    let mut panels: Vec<Panel> = vec![(format!("GROUND TRUTH: {} PTS", gt.len()), &gt, None)];
    panels.extend(
        clouds
            .iter()
            .map(|(t, p, d)| (t.clone(), p.as_slice(), Some(d.as_slice()))),
    );
    error_figure(&panels, &gt, CLOUD_VIEW, 480, ERROR_VMAX, "DISTANCE TO GT").save(path)?;
    Ok(format!(
        "## Point clouds coloured by error\n\nOrthographic view (azimuth {}°, elevation {}°) of \
         the ground truth (grey) and of the predicted points, each coloured by its distance to \
         the nearest ground-truth point on the Turbo scale under the panels: dark blue = 0, \
         green ≈ {}, dark red ≥ {ERROR_VMAX} Blender units (the F-score threshold is 0.01).\n",
        CLOUD_VIEW.0,
        CLOUD_VIEW.1,
        ERROR_VMAX / 2.0
    ))
}

/// The meshes `extract --mesh` wrote for the best Plenoxels level and αSurf, shaded, in the view
/// of the point-cloud figure.
fn meshes(r: &Inputs, path: &Path) -> Result<String> {
    let gt = read_points(&r.data.join("gt_points.ply"))?;
    let proj = Projection::fit(&gt, CLOUD_VIEW.0, CLOUD_VIEW.1, 480, 480);
    let mut panels = Vec::new();
    let mut files = Vec::new();
    for row in r
        .rows
        .iter()
        .filter(|x| x.kind == "plenoxels_best" || x.kind == "alphasurf")
    {
        let file = super::mesh_path(row);
        if !file.is_file() {
            continue;
        }
        let m = read_mesh_ply(&file)?;
        let label = match row.level {
            Some(l) => format!("PLENOXELS σ = {l}"),
            None => "αSURF".to_string(),
        };
        panels.push((
            format!("{label}: {} FACES", m.faces.len()),
            render_mesh(&m.positions, &m.faces, &proj),
        ));
        files.push(format!("`{}`", rel(r.out, &file)));
    }
    anyhow::ensure!(!panels.is_empty(), "no mesh was written");
    side_by_side(&panels, 2).save(path)?;
    Ok(format!(
        "## Meshes\n\n`alphasurf extract --mesh` (marching tetrahedra on the trilinear field; \
         {}), shaded, in the view of the point clouds. Every level's surface is in the mesh \
         (αSurf: faces with σα ≥ 0.1).\n",
        files.join(", ")
    ))
}

/// Batch MSE and PSNR against the step, stage 2 continuing after stage 1; moving averages.
fn curves(r: &Inputs, path: &Path) -> Result<String> {
    let log_name = crate::run::dir::TRAIN_LOG;
    let mut stages = vec![("STAGE 1 (PLENOXELS)", log::read(&r.s1.dir.join(log_name))?)];
    let mut s2_note = String::new();
    if let Ok(s2) = &r.s2 {
        match log::read(&s2.dir.join(log_name)) {
            Ok(rows) => stages.push(("STAGE 2 (αSURF)", rows)),
            Err(e) => s2_note = format!(" Stage 2 wrote no usable log ({e:#})."),
        }
    }
    let mut mse = Vec::new();
    let mut psnr = Vec::new();
    let mut offset = 0u32;
    for (k, (name, rows)) in stages.iter().enumerate() {
        let win = (rows.len() / 60).max(1);
        let steps: Vec<f64> = rows.iter().map(|x| (x.step + offset) as f64).collect();
        let m = log::smooth(&rows.iter().map(|x| x.mse).collect::<Vec<_>>(), win);
        let p = log::smooth(&rows.iter().map(|x| x.psnr).collect::<Vec<_>>(), win);
        for (dst, v) in [(&mut mse, m), (&mut psnr, p)] {
            dst.push(Series {
                label: name.to_string(),
                points: steps.iter().copied().zip(v).collect(),
                colour: PALETTE[k],
                style: Style::Line,
                point_labels: vec![],
            });
        }
        offset += rows.last().map_or(0, |x| x.step);
    }
    let (w, h) = (640i64, 440i64);
    let mut c = Canvas::new(2 * w as u32, h as u32, WHITE);
    let x = Axis {
        label: "TRAINING STEP".into(),
        log: false,
    };
    plot::draw(
        &mut c,
        (0, 0, w, h),
        &Plot {
            title: "TRAINING LOSS (BATCH MSE)".into(),
            x: x.clone(),
            y: Axis {
                label: "MSE".into(),
                log: true,
            },
        },
        &mse,
    );
    plot::draw(
        &mut c,
        (w, 0, w, h),
        &Plot {
            title: "TRAINING PSNR (BATCH)".into(),
            x,
            y: Axis {
                label: "PSNR (DB)".into(),
                log: false,
            },
        },
        &psnr,
    );
    c.save(path)?;
    Ok(format!(
        "## Training curves\n\nPer-step batch MSE (log scale) and batch PSNR from each run's \
         `train_log.csv`, as moving averages over ~1/60 of the run; stage 2's steps continue \
         after stage 1's.{s2_note} Final test PSNR: stage 1 {:.2} dB{}.\n",
        r.s1.test_psnr,
        match &r.s2 {
            Ok(s2) => format!(", stage 2 {:.2} dB", s2.test_psnr),
            Err(_) => String::new(),
        }
    ))
}

/// Chamfer ×10⁻² of each Plenoxels level, with αSurf's as a horizontal line.
fn chamfer_levels(r: &Inputs, path: &Path) -> Result<String> {
    let plen: Vec<(f64, f64)> = r
        .rows
        .iter()
        .filter(|x| x.kind == "plenoxels")
        .filter_map(|x| Some((x.level? as f64, x.chamfer_e2?)))
        .collect();
    anyhow::ensure!(!plen.is_empty(), "no Plenoxels level was evaluated");
    let mut series = vec![Series {
        label: "PLENOXELS σ = τ".into(),
        points: plen.clone(),
        colour: PALETTE[0],
        style: Style::LineMarkers,
        point_labels: vec![],
    }];
    if let Some(a) = r
        .rows
        .iter()
        .find(|x| x.kind == "alphasurf")
        .and_then(|x| x.chamfer_e2)
    {
        let (lo, hi) = plen.iter().fold((f64::MAX, f64::MIN), |(lo, hi), p| {
            (lo.min(p.0), hi.max(p.0))
        });
        series.push(Series {
            label: "αSURF".into(),
            points: vec![(lo, a), (hi, a)],
            colour: PALETTE[1],
            style: Style::Line,
            point_labels: vec![],
        });
    }
    plot::single(
        720,
        440,
        &Plot {
            title: "CHAMFER VS DENSITY LEVEL".into(),
            x: Axis {
                label: "LEVEL τ (DENSITY)".into(),
                log: false,
            },
            y: Axis {
                label: "CHAMFER ×0.01".into(),
                log: false,
            },
        },
        &series,
    )
    .save(path)?;
    Ok(format!(
        "## Chamfer against the density level\n\nThe Plenoxels baseline's Chamfer ×10⁻² at each \
         level τ of the sweep{}. Lower is better.\n",
        if series.len() > 1 {
            "; the horizontal line is αSurf's"
        } else {
            ""
        }
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{Rgb, RgbImage};

    #[test]
    fn most_covered_picks_the_view_with_most_object() {
        let mut a = RgbImage::from_pixel(8, 8, Rgb([255; 3]));
        let mut b = a.clone();
        a.put_pixel(0, 0, Rgb([0; 3]));
        for x in 0..4 {
            b.put_pixel(x, 1, Rgb([10, 200, 30]));
        }
        assert_eq!(most_covered(&[a.clone(), b, a]), 1);
        assert_eq!(most_covered(&[]), 0);
    }
}
