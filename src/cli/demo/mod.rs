//! `alphasurf demo`: the whole method on a built-in scene, through the user-facing commands run
//! in-process ([`steps`]): make-scene → stage 1 (`train --stage plenoxels`) → the Plenoxels
//! level-set sweep (`extract` + `eval` at σ ∈ {10, 30, 50, 70, 90, 100}) → stage 2
//! (`train --stage surface`) → `extract` → `eval`. Prints one table (method | Chamfer ×10⁻² | F1 |
//! test PSNR | wall time) and writes `report.md` with PNG figures ([`report`]) and
//! `results.json`.

pub mod report;
pub mod steps;

use super::extract::DEFAULT_RAYS_PER_AXIS;
use super::Cli;
use crate::backend::Backend;
use crate::eval::Metrics;
use crate::scene::SceneKind;
use crate::train::Category;
use anyhow::{Context, Result};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;
use steps::{Invoker, SceneSize, TrainSize, TrainedRun};

/// The density levels of the Plenoxels baseline sweep (the paper's).
pub const LEVELS: [f32; 6] = [10.0, 30.0, 50.0, 70.0, 90.0, 100.0];

/// Arguments of `demo`.
#[derive(clap::Args, Debug)]
pub struct DemoArgs {
    /// Which built-in scene.
    #[arg(long, value_enum, default_value = "thin")]
    pub scene: SceneKind,
    /// A smaller run (128² images, 40 views, 64³ grid, 1000 + 600 steps) instead of the default
    /// (256² images, 100 views, stage-1 preset `fast`: 128³, 3000 steps).
    #[arg(long)]
    pub fast: bool,
    /// Output directory (default: runs/demo-SCENE, or runs/demo-SCENE-fast with --fast).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Where the kernels run (resolved once, then passed to every step).
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    pub backend: Backend,
    /// Virtual rays per axis and cell for every extraction (`extract --rays-per-axis`, the same
    /// for both methods), 1 ..= 64. 5 is method.md's 75 rays per cell; 17 on the 128³ grid
    /// samples as densely as the paper's 5 on its 512³ grid (a quarter of a 512³ voxel). Denser
    /// clouds lower both methods' Chamfer distance and take longer to extract and evaluate.
    #[arg(long, default_value_t = DEFAULT_RAYS_PER_AXIS, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub rays_per_axis: u32,
    #[command(flatten)]
    pub size: SizeArgs,
}

/// Size overrides of the demo and the time-vs-error bench (hidden: for tests and experiments).
#[derive(clap::Args, Debug, Clone, Default)]
pub struct SizeArgs {
    /// Image width and height of the generated scene.
    #[arg(long, hide = true)]
    pub image_res: Option<u32>,
    /// Training views of the generated scene.
    #[arg(long, hide = true)]
    pub views: Option<u32>,
    /// Samples per pixel along each axis of the generated scene.
    #[arg(long, hide = true)]
    pub spp: Option<u32>,
    /// Ground-truth point spacing of the generated scene.
    #[arg(long, hide = true)]
    pub gt_spacing: Option<f64>,
    /// Final grid resolution N (stage 1 `train --res N`: preset `fast`'s 3000 steps, upsampling
    /// to N³ at step 1000; stage 2 then starts from that grid), 8 ..= 1024. Default 128 (64 with
    /// `--fast`). 512 is the paper's grid; time and memory grow with N³ (docs/results.md has
    /// measured runs).
    #[arg(long, value_parser = clap::value_parser!(u32).range(8..=1024))]
    pub grid_res: Option<u32>,
    /// Stage-1 steps.
    #[arg(long, hide = true)]
    pub iters: Option<u32>,
    /// Stage-1 rays per batch.
    #[arg(long, hide = true)]
    pub batch: Option<u32>,
    /// Stage-2 steps.
    #[arg(long, hide = true)]
    pub surface_iters: Option<u32>,
    /// Stage-2 configuration overrides, passed on as `train --set KEY=VALUE`. Repeatable.
    #[arg(long, hide = true, value_name = "KEY=VALUE")]
    pub surface_set: Vec<String>,
}

impl SizeArgs {
    /// The scene size: the overrides over the default or `--fast` sizes.
    pub fn scene(&self, fast: bool) -> SceneSize {
        let base = if fast {
            SceneSize {
                image_res: 128,
                views: 40,
                spp: 2,
                gt_spacing: 0.0019,
            }
        } else {
            SceneSize {
                image_res: 256,
                views: 100,
                spp: 4,
                gt_spacing: 0.0019,
            }
        };
        SceneSize {
            image_res: self.image_res.unwrap_or(base.image_res),
            views: self.views.unwrap_or(base.views),
            spp: self.spp.unwrap_or(base.spp),
            gt_spacing: self.gt_spacing.unwrap_or(base.gt_spacing),
        }
    }

    /// The stage-1 size: preset `fast` as is, or 64³ and 1000 steps with `--fast`.
    pub fn train(&self, fast: bool) -> TrainSize {
        TrainSize {
            res: self.grid_res.or(fast.then_some(64)),
            iters: self.iters.or(fast.then_some(1000)),
            batch: self.batch,
        }
    }

    /// Stage-2 steps (`None`: the preset's).
    pub fn surface_iters(&self, fast: bool) -> Option<u32> {
        self.surface_iters.or(fast.then_some(600))
    }
}

/// One row of the results table.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    /// As printed: "Plen σ = 10", "best Plen (σ = 50)", "αSurf".
    pub method: String,
    /// "plenoxels", "plenoxels_best" or "alphasurf".
    pub kind: String,
    /// Density level of a Plenoxels row.
    pub level: Option<f32>,
    /// The evaluated point cloud.
    pub ply: PathBuf,
    /// `eval`'s metrics (None when a step failed).
    pub metrics: Option<Metrics>,
    /// Chamfer ×10⁻² (Blender units × 100).
    pub chamfer_e2: Option<f64>,
    pub f1: Option<f64>,
    /// Mean test-view PSNR of the run the cloud came from.
    pub test_psnr: Option<f64>,
    /// Wall time of the commands that produced the cloud: training (stage 1, plus stage 2 for
    /// αSurf) and extraction.
    pub wall_s: f64,
    /// Why a step failed.
    pub error: Option<String>,
}

impl Row {
    fn new(method: String, kind: &str, level: Option<f32>, ply: PathBuf) -> Row {
        Row {
            method,
            kind: kind.into(),
            level,
            ply,
            metrics: None,
            chamfer_e2: None,
            f1: None,
            test_psnr: None,
            wall_s: f64::NAN,
            error: None,
        }
    }

    fn set_metrics(&mut self, m: Metrics) {
        self.chamfer_e2 = Some(m.chamfer * 100.0);
        self.f1 = Some(m.f1);
        self.metrics = Some(m);
    }
}

/// Extract and evaluate one point cloud: `extract` then `eval`. Failures are kept in the row.
fn extract_eval(inv: &Invoker, run: &TrainedRun, gt: &Path, mut row: Row, train_s: f64) -> Row {
    let levels = row.level.map(|l| vec![l]);
    let r = inv
        .extract(&run.dir, &row.ply, levels.as_deref())
        .and_then(|extract_s| Ok((extract_s, inv.eval(&row.ply, gt)?)));
    row.test_psnr = Some(run.test_psnr);
    match r {
        Ok((extract_s, m)) => {
            row.wall_s = train_s + extract_s;
            row.set_metrics(m);
        }
        Err(e) => {
            eprintln!("demo: {}: {e:#}", row.method);
            row.error = Some(format!("{e:#}"));
        }
    }
    row
}

/// The Plenoxels baseline "Plen (σ = τ)": extract and evaluate the stage-1 grid at each level.
pub fn plenoxels_levels(inv: &Invoker, s1: &TrainedRun, gt: &Path, levels: &[f32]) -> Vec<Row> {
    levels
        .iter()
        .map(|&l| {
            let row = Row::new(
                format!("Plen σ = {l}"),
                "plenoxels",
                Some(l),
                s1.dir.join(format!("points_sigma{l}.ply")),
            );
            extract_eval(inv, s1, gt, row, s1.wall_s)
        })
        .collect()
}

/// The level with the lowest Chamfer distance, as a "best Plen" row.
pub fn best_plenoxels(rows: &[Row]) -> Option<Row> {
    let best = rows
        .iter()
        .filter(|r| r.kind == "plenoxels" && r.chamfer_e2.is_some_and(f64::is_finite))
        .min_by(|a, b| a.chamfer_e2.unwrap().total_cmp(&b.chamfer_e2.unwrap()))?;
    let mut r = best.clone();
    r.method = format!("best Plen (σ = {})", r.level.unwrap_or(f32::NAN));
    r.kind = "plenoxels_best".into();
    Some(r)
}

/// Stage 2 (αSurf) from the stage-1 run: `train --stage surface --init S1 --category C --preset
/// fast [--iters N] [--set K=V]…`. An error (e.g. the command not existing yet in this build) is
/// returned to the caller, who reports it.
#[allow(clippy::too_many_arguments)]
pub fn stage2(
    inv: &Invoker,
    s1: &TrainedRun,
    data: &Path,
    out: &Path,
    scene: SceneKind,
    iters: Option<u32>,
    set: &[String],
    progress: bool,
) -> Result<TrainedRun> {
    let category = match scene {
        SceneKind::Thin => Category::Thin,
        SceneKind::Translucent => Category::Translucent,
        SceneKind::Solid => Category::Synthetic,
    };
    inv.train_surface(&s1.dir, data, out, category, iters, set, progress)
}

/// αSurf's row: extract (α ≥ 0.1) and evaluate the stage-2 run.
pub fn alphasurf_row(inv: &Invoker, s1: &TrainedRun, s2: &TrainedRun, gt: &Path) -> Row {
    let row = Row::new("αSurf".into(), "alphasurf", None, s2.dir.join("points.ply"));
    extract_eval(inv, s2, gt, row, s1.wall_s + s2.wall_s)
}

/// Text of a table cell for an optional number.
fn cell(v: Option<f64>, prec: usize, unit: &str) -> String {
    match v {
        Some(x) if x.is_finite() => format!("{x:.prec$}{unit}"),
        _ => "—".into(),
    }
}

/// The results table as plain text (`markdown`: as a markdown table).
pub fn table(rows: &[Row], markdown: bool) -> String {
    let head = ["method", "Chamfer ×10⁻²", "F1", "test PSNR", "wall time"];
    let body: Vec<Vec<String>> = rows
        .iter()
        .map(|r| {
            vec![
                r.method.clone(),
                cell(r.chamfer_e2, 4, ""),
                cell(r.f1, 4, ""),
                cell(r.test_psnr, 2, " dB"),
                if r.error.is_some() {
                    "failed".into()
                } else {
                    cell(Some(r.wall_s), 1, " s")
                },
            ]
        })
        .collect();
    layout(&head, &body, markdown)
}

/// Where the Chamfer distance comes from: each object group's share of it (`eval`'s split over
/// the scene's objects) for the best Plenoxels level and for αSurf, largest Plenoxels share
/// first. None unless both rows have the split.
pub fn objects_table(best: &Row, surf: &Row, markdown: bool) -> Option<String> {
    let (b, a) = (
        &best.metrics.as_ref()?.objects,
        &surf.metrics.as_ref()?.objects,
    );
    if b.is_empty() || b.len() != a.len() {
        return None;
    }
    let mut pairs: Vec<_> = b.iter().zip(a).filter(|(b, a)| b.name == a.name).collect();
    pairs.sort_by(|x, y| y.0.chamfer_share.total_cmp(&x.0.chamfer_share));
    let head = [
        "object group",
        "GT points",
        "best Plen share",
        "αSurf share",
        "change",
    ];
    let body: Vec<Vec<String>> = pairs
        .iter()
        .map(|(b, a)| {
            let change = 100.0 * (a.chamfer_share - b.chamfer_share) / b.chamfer_share;
            vec![
                b.name.clone(),
                b.n_gt.to_string(),
                cell(Some(100.0 * b.chamfer_share), 4, ""),
                cell(Some(100.0 * a.chamfer_share), 4, ""),
                if change.is_finite() {
                    format!("{change:+.1} %")
                } else {
                    "—".into()
                },
            ]
        })
        .collect();
    Some(layout(&head, &body, markdown))
}

/// A table with a left-aligned first column and right-aligned others, as aligned plain text or
/// (`markdown`) a markdown table.
fn layout(head: &[&str], body: &[Vec<String>], markdown: bool) -> String {
    let mut s = String::new();
    if markdown {
        s += &format!(
            "| {} |\n|---{}|\n",
            head.join(" | "),
            "|---:".repeat(head.len() - 1)
        );
        for r in body {
            s += &format!("| {} |\n", r.join(" | "));
        }
        return s;
    }
    let w: Vec<usize> = (0..head.len())
        .map(|i| {
            body.iter()
                .map(|r| r[i].chars().count())
                .chain([head[i].chars().count()])
                .max()
                .unwrap_or(0)
        })
        .collect();
    let line = |c: Vec<&str>| {
        let mut l = format!("{:<w0$}", c[0], w0 = w[0]);
        for i in 1..c.len() {
            let pad = w[i] - c[i].chars().count();
            l += &format!("  {}{}", " ".repeat(pad), c[i]);
        }
        l + "\n"
    };
    s += &line(head.to_vec());
    for r in body {
        s += &line(r.iter().map(String::as_str).collect());
    }
    s
}

fn phase(i: usize, n: usize, msg: &str) {
    eprintln!("\n=== demo [{i}/{n}] {msg}");
}

/// Run `demo`.
pub fn run(args: &DemoArgs, cli: &Cli) -> Result<()> {
    let t0 = Instant::now();
    let scene = args.scene;
    let out = args.out.clone().unwrap_or_else(|| {
        PathBuf::from(format!(
            "runs/demo-{}{}",
            scene.name(),
            if args.fast { "-fast" } else { "" }
        ))
    });
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let inv = Invoker::new(args.backend, cli)?.with_rays_per_axis(args.rays_per_axis);
    // The training commands draw a bar on a terminal and log every 10 % otherwise.
    let progress = true;
    let (data, s1_dir, s2_dir) = (
        out.join("scene"),
        out.join("plenoxels"),
        out.join("alphasurf"),
    );
    let gt = data.join("gt_points.ply");
    let size = args.size.scene(args.fast);
    let n = 6;

    phase(
        1,
        n,
        &format!(
            "make-scene --kind {} ({}² images, {} training views) → {}",
            scene.name(),
            size.image_res,
            size.views,
            data.display()
        ),
    );
    inv.make_scene(scene, &data, &size)?;

    let tsize = args.size.train(args.fast);
    phase(
        2,
        n,
        &format!(
            "stage 1: train --stage plenoxels --preset fast{}{} on {} → {}",
            tsize.res.map_or(String::new(), |r| format!(" --res {r}")),
            tsize
                .iters
                .map_or(String::new(), |i| format!(" --iters {i}")),
            inv.backend,
            s1_dir.display()
        ),
    );
    let s1 = inv.train_plenoxels(&data, &s1_dir, &tsize, progress)?;

    phase(
        3,
        n,
        &format!(
            "Plenoxels level-set sweep: extract ({}² rays per axis and cell) + eval at σ ∈ {LEVELS:?}",
            inv.rays_per_axis
        ),
    );
    let mut rows = plenoxels_levels(&inv, &s1, &gt, &LEVELS);
    let best = best_plenoxels(&rows);

    phase(
        4,
        n,
        &format!(
            "stage 2 (αSurf): train --stage surface --init {} → {}",
            s1_dir.display(),
            s2_dir.display()
        ),
    );
    let s2 = stage2(
        &inv,
        &s1,
        &data,
        &s2_dir,
        scene,
        args.size.surface_iters(args.fast),
        &args.size.surface_set,
        progress,
    );
    if let Err(e) = &s2 {
        eprintln!("demo: STAGE 2 FAILED — the table shows the Plenoxels rows only.\n  {e:#}");
    }

    phase(5, n, "αSurf: extract (α ≥ 0.1) + eval");
    let surf = match &s2 {
        Ok(s2) => Some(alphasurf_row(&inv, &s1, s2, &gt)),
        Err(_) => {
            eprintln!("demo: skipped (no stage-2 run)");
            None
        }
    };
    rows.extend(best.clone());
    rows.extend(surf);

    phase(
        6,
        n,
        &format!("report → {}", out.join("report.md").display()),
    );
    let rep = report::Inputs {
        scene,
        out: &out,
        data: &data,
        s1: &s1,
        s2: s2.as_ref().map_err(|e| format!("{e:#}")),
        rows: &rows,
        fast: args.fast,
        backend: inv.backend,
        rays_per_axis: inv.rays_per_axis,
        grid_res: args.size.grid_res,
        elapsed_s: t0.elapsed().as_secs_f64(),
    };
    let files = report::write(&rep)?;

    println!();
    print!("{}", table(&rows, false));
    if let Some(t) = best
        .as_ref()
        .zip(rows.iter().find(|r| r.kind == "alphasurf"))
        .and_then(|(b, a)| objects_table(b, a, false))
    {
        println!("\nwhere the Chamfer distance comes from (×10⁻², shares add up to it):");
        print!("{t}");
    }
    if let (Some(b), Some(a)) = (
        best.as_ref().and_then(|b| b.chamfer_e2),
        rows.iter()
            .find(|r| r.kind == "alphasurf")
            .and_then(|r| r.chamfer_e2),
    ) {
        println!(
            "αSurf Chamfer vs best Plenoxels level: {:+.1} %",
            100.0 * (a - b) / b
        );
    }
    if let Err(e) = &s2 {
        println!(
            "stage 2 (αSurf) did not run: {}",
            first_line(&format!("{e:#}"))
        );
    }
    println!(
        "demo done in {:.1} s: {} ({} figures)",
        t0.elapsed().as_secs_f64(),
        out.join("report.md").display(),
        files.len()
    );
    Ok(())
}

/// First line of a message.
pub fn first_line(s: &str) -> &str {
    s.lines().next().unwrap_or("")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(method: &str, kind: &str, level: Option<f32>, chamfer: Option<f64>) -> Row {
        let mut r = Row::new(method.into(), kind, level, PathBuf::from("x.ply"));
        r.chamfer_e2 = chamfer;
        r.f1 = chamfer.map(|_| 0.5);
        r.wall_s = 12.0;
        r.test_psnr = Some(25.0);
        r
    }

    #[test]
    fn best_level_is_the_lowest_finite_chamfer() {
        let rows = vec![
            row("Plen σ = 10", "plenoxels", Some(10.0), Some(0.9)),
            row("Plen σ = 30", "plenoxels", Some(30.0), Some(0.6)),
            row("Plen σ = 50", "plenoxels", Some(50.0), None),
            row("Plen σ = 70", "plenoxels", Some(70.0), Some(f64::NAN)),
            row("αSurf", "alphasurf", None, Some(0.1)),
        ];
        let b = best_plenoxels(&rows).unwrap();
        assert_eq!(b.level, Some(30.0));
        assert_eq!(b.method, "best Plen (σ = 30)");
        assert_eq!(b.kind, "plenoxels_best");
        assert!(best_plenoxels(&rows[2..4]).is_none());
    }

    #[test]
    fn tables_align_and_show_failures() {
        let mut failed = row("αSurf", "alphasurf", None, None);
        failed.error = Some("boom".into());
        let rows = vec![
            row("Plen σ = 10", "plenoxels", Some(10.0), Some(0.91234)),
            failed,
        ];
        let t = table(&rows, false);
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines.len(), 3);
        let w = lines[0].chars().count();
        assert!(lines.iter().all(|l| l.chars().count() == w), "{t}");
        assert!(lines[1].contains("0.9123") && lines[1].contains("25.00 dB"));
        assert!(lines[2].contains("failed") && lines[2].contains('—'));
        let md = table(&rows, true);
        assert!(md.starts_with("| method | Chamfer ×10⁻² |"));
        assert_eq!(md.lines().count(), 4);
    }

    #[test]
    fn object_table_compares_shares_largest_plenoxels_share_first() {
        use crate::eval::metrics::from_distances;
        use crate::eval::objects::GroupError;
        let with = |shares: [f64; 2]| {
            let mut r = row("x", "plenoxels", None, Some(1.0));
            let mut m = from_distances(&[0.1], &[0.2], &Default::default());
            m.objects = ["wire", "pot"]
                .iter()
                .zip(shares)
                .map(|(n, s)| GroupError {
                    name: n.to_string(),
                    n_gt: 7,
                    n_pred: 3,
                    mean_d2s: 0.1,
                    mean_s2d: 0.2,
                    chamfer_share: s,
                })
                .collect();
            r.metrics = Some(m);
            r
        };
        let (b, a) = (with([0.001, 0.004]), with([0.0005, 0.005]));
        let t = objects_table(&b, &a, false).unwrap();
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines.len(), 3, "{t}");
        assert!(
            lines[1].starts_with("pot") && lines[1].ends_with("+25.0 %"),
            "{t}"
        );
        assert!(
            lines[2].starts_with("wire") && lines[2].ends_with("-50.0 %"),
            "{t}"
        );
        assert!(
            lines[2].contains("0.1000") && lines[2].contains("0.0500"),
            "{t}"
        );
        let w = lines[0].chars().count();
        assert!(lines.iter().all(|l| l.chars().count() == w), "{t}");
        assert_eq!(objects_table(&b, &a, true).unwrap().lines().count(), 4);
        let mut bare = with([0.0; 2]);
        bare.metrics.as_mut().unwrap().objects.clear();
        assert!(objects_table(&bare, &a, false).is_none());
        assert!(objects_table(&row("y", "alphasurf", None, None), &a, false).is_none());
    }
}
