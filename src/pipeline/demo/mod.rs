//! `demo` as a library call: the whole method on a built-in scene, step by step ([`super::steps`]):
//! make-scene → stage 1 (`train --stage plenoxels`) → the Plenoxels level-set sweep (`extract` +
//! `eval` at σ ∈ {10, 30, 50, 70, 90, 100}) → stage 2 (`train --stage surface`) → `extract` →
//! `eval`, then `extract --mesh` of the best level and of αSurf. Returns the results table's rows
//! (method | Chamfer ×10⁻² | F1 | test PSNR | wall time) and writes `report.md` with PNG figures
//! ([`report`]) and `results.json`.

pub mod report;
pub mod table;

pub use table::{objects_table, table};

use super::device::Devices;
use super::extract::{LevelJob, DEFAULT_RAYS_PER_AXIS};
use super::steps::{PlenoxelsOverrides, SceneSize, Steps, SurfaceOverrides, TrainedRun};
use crate::backend::Backend;
use crate::eval::Metrics;
use crate::run::interrupt;
use crate::scene::SceneKind;
use crate::train::Category;
use anyhow::{Context, Result};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The density levels of the Plenoxels baseline sweep (the paper's).
pub const LEVELS: [f32; 6] = [10.0, 30.0, 50.0, 70.0, 90.0, 100.0];

/// Options of `demo` (its command-line flags).
#[derive(clap::Args, Debug)]
pub struct DemoOptions {
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
    pub fn train(&self, fast: bool) -> PlenoxelsOverrides {
        PlenoxelsOverrides {
            res: self.grid_res.or(fast.then_some(64)),
            iters: self.iters.or(fast.then_some(1000)),
            batch: self.batch,
            set: Vec::new(),
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
fn extract_eval(steps: &Steps, run: &TrainedRun, gt: &Path, row: Row, train_s: f64) -> Row {
    let levels = row.level.map(|l| vec![l]);
    let r = steps
        .extract(&run.dir, &row.ply, levels.as_deref())
        .and_then(|extract_s| Ok((extract_s, steps.eval(&row.ply, gt)?)));
    scored(row, run, r, train_s)
}

/// The row with its figures (`r`: the extraction's seconds and the metrics), or its failure;
/// each printed.
fn scored(mut row: Row, run: &TrainedRun, r: Result<(f64, Metrics)>, train_s: f64) -> Row {
    row.test_psnr = Some(run.test_psnr);
    match r {
        Ok((extract_s, m)) => {
            eprintln!(
                "  {}: {} points, Chamfer ×10⁻² {:.4}, F1 {:.4}",
                row.method,
                m.n_pred,
                m.chamfer * 100.0,
                m.f1
            );
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

/// The Plenoxels baseline "Plen (σ = τ)": the stage-1 grid extracted at each level and evaluated.
pub fn plenoxels_levels(steps: &Steps, s1: &TrainedRun, gt: &Path, levels: &[f32]) -> Vec<Row> {
    level_sweep(steps, s1, gt, levels, None)
}

/// The same levels with αSurf's extraction rules for thin scenes: hidden cells trimmed
/// (`extract --trim-hidden on`) and thin sheets' points centred (`--sheets on`); the clouds go
/// to `dir`.
pub fn plenoxels_levels_trimmed(
    steps: &Steps,
    s1: &TrainedRun,
    gt: &Path,
    levels: &[f32],
    dir: &Path,
) -> Vec<Row> {
    level_sweep(steps, s1, gt, levels, Some(dir))
}

/// Extract and evaluate the stage-1 run `s1` at each level (into its run directory; with the
/// hidden cells trimmed and thin sheets centred into `trimmed_into` when given): the grid read
/// once, the ground truth read once. Failures are kept in their rows.
fn level_sweep(
    steps: &Steps,
    s1: &TrainedRun,
    gt: &Path,
    levels: &[f32],
    trimmed_into: Option<&Path>,
) -> Vec<Row> {
    let jobs: Vec<LevelJob> = levels
        .iter()
        .map(|&level| LevelJob {
            level,
            trim_hidden: trimmed_into.is_some(),
            centre_sheets: trimmed_into.is_some(),
            out: match trimmed_into {
                None => s1.dir.join(format!("points_sigma{level}.ply")),
                Some(dir) => dir.join(format!("points_sigma{level}_trimmed.ply")),
            },
        })
        .collect();
    let extracted = match steps.extract_levels(&s1.dir, &jobs) {
        Ok(each) => each,
        Err(e) => jobs.iter().map(|_| Err(anyhow::anyhow!("{e:#}"))).collect(),
    };
    let truth = steps.ground_truth(gt).map_err(|e| format!("{e:#}"));
    let (suffix, kind) = match trimmed_into {
        None => ("", "plenoxels"),
        Some(_) => (", hidden cells trimmed", "plenoxels_trimmed"),
    };
    jobs.into_iter()
        .zip(extracted)
        .map(|(job, extract)| {
            let row = Row::new(
                format!("Plen σ = {}{suffix}", job.level),
                kind,
                Some(job.level),
                job.out,
            );
            let r = extract.and_then(|extract_s| match &truth {
                Ok(truth) => Ok((extract_s, steps.eval_against(&row.ply, truth)?)),
                Err(e) => Err(anyhow::anyhow!("{e}")),
            });
            scored(row, s1, r, s1.wall_s)
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

/// The stage-2 category of a built-in scene.
pub fn category(scene: SceneKind) -> Category {
    match scene {
        SceneKind::Thin => Category::Thin,
        SceneKind::Translucent => Category::Translucent,
        SceneKind::Solid => Category::Synthetic,
    }
}

/// αSurf's row: extract (α ≥ 0.1) and evaluate the stage-2 run.
pub fn alphasurf_row(steps: &Steps, s1: &TrainedRun, s2: &TrainedRun, gt: &Path) -> Row {
    let row = Row::new("αSurf".into(), "alphasurf", None, s2.dir.join("points.ply"));
    extract_eval(steps, s2, gt, row, s1.wall_s + s2.wall_s)
}

/// Where the mesh of a row's surfaces goes: its point cloud's name with "points" → "mesh".
pub fn mesh_path(row: &Row) -> PathBuf {
    let name = row.ply.file_name().map_or_else(
        || "mesh.ply".to_string(),
        |n| n.to_string_lossy().replacen("points", "mesh", 1),
    );
    row.ply.with_file_name(name)
}

/// `extract --mesh` for the best Plenoxels level and αSurf (the rows that were evaluated); a
/// failure is reported and leaves that mesh out.
fn write_meshes(steps: &Steps, rows: &[Row], s1: &TrainedRun, s2: Option<&TrainedRun>) {
    for row in rows.iter().filter(|r| r.error.is_none()) {
        let (run, levels) = match (row.kind.as_str(), s2) {
            ("plenoxels_best", _) => (s1, row.level.map(|l| vec![l])),
            ("alphasurf", Some(s2)) => (s2, None),
            _ => continue,
        };
        if let Err(e) = steps.extract_mesh(&run.dir, &mesh_path(row), levels.as_deref()) {
            eprintln!("demo: mesh of {}: {e:#}", row.method);
        }
    }
}

fn phase(i: usize, n: usize, msg: &str) {
    eprintln!("\n=== demo [{i}/{n}] {msg}");
}

/// What `demo` produced.
pub struct DemoSummary {
    /// The table's rows: every level, the best level, αSurf.
    pub rows: Vec<Row>,
    /// Why stage 2 did not run.
    pub stage2_error: Option<String>,
    /// `report.md`.
    pub report: PathBuf,
    pub figures: usize,
    pub elapsed_s: f64,
}

impl DemoSummary {
    /// The best Plenoxels level's row.
    pub fn best(&self) -> Option<&Row> {
        self.rows.iter().find(|r| r.kind == "plenoxels_best")
    }

    /// αSurf's row.
    pub fn alphasurf(&self) -> Option<&Row> {
        self.rows.iter().find(|r| r.kind == "alphasurf")
    }
}

/// How many phases `demo` announces.
const DEMO_PHASES: usize = 6;

/// Run the demo on the device `devices` holds for `opts.backend`.
pub fn demo(opts: &DemoOptions, devices: &mut Devices) -> Result<DemoSummary> {
    let t0 = Instant::now();
    let scene = opts.scene;
    let out = opts.out.clone().unwrap_or_else(|| {
        PathBuf::from(format!(
            "runs/demo-{}{}",
            scene.name(),
            if opts.fast { "-fast" } else { "" }
        ))
    });
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    // `auto` is resolved once, so the steps do not each probe the device.
    let steps = Steps {
        rays_per_axis: opts.rays_per_axis,
        ..Steps::new(devices.for_backend(opts.backend)?)
    };
    let (data, s1_dir, s2_dir) = (
        out.join("scene"),
        out.join("plenoxels"),
        out.join("alphasurf"),
    );
    let gt = data.join("gt_points.ply");
    let n = DEMO_PHASES;
    let s1 = demo_scene_and_stage1(&steps, opts, &data, &s1_dir)?;

    phase(
        3,
        n,
        &format!(
            "Plenoxels level-set sweep: extract ({}² rays per axis and cell) + eval at σ ∈ {LEVELS:?}",
            steps.rays_per_axis
        ),
    );
    let mut rows = plenoxels_levels(&steps, &s1, &gt, &LEVELS);
    let best = best_plenoxels(&rows);

    let s2 = demo_stage2(&steps, opts, &s1, &data, &s1_dir, &s2_dir)?;

    phase(5, n, "αSurf: extract (α ≥ 0.1) + eval");
    let surf = match &s2 {
        Ok(s2) => Some(alphasurf_row(&steps, &s1, s2, &gt)),
        Err(_) => {
            eprintln!("demo: skipped (no stage-2 run)");
            None
        }
    };
    rows.extend(best);
    rows.extend(surf);
    eprintln!("\ndemo: meshes (extract --mesh) of the best Plenoxels level and αSurf");
    write_meshes(&steps, &rows, &s1, s2.as_ref().ok());

    let report = out.join("report.md");
    phase(6, n, &format!("report → {}", report.display()));
    let rep = report::Inputs {
        scene,
        out: &out,
        data: &data,
        s1: &s1,
        s2: s2.as_ref().map_err(|e| format!("{e:#}")),
        rows: &rows,
        fast: opts.fast,
        backend: steps.backend(),
        rays_per_axis: steps.rays_per_axis,
        grid_res: opts.size.grid_res,
        elapsed_s: t0.elapsed().as_secs_f64(),
    };
    let figures = report::write(&rep)?.len();
    Ok(DemoSummary {
        stage2_error: s2.err().map(|e| format!("{e:#}")),
        rows,
        report,
        figures,
        elapsed_s: t0.elapsed().as_secs_f64(),
    })
}

/// Demo phases 1 and 2: the built-in scene written to `data`, then stage 1 (Plenoxels)
/// trained on it into `s1_dir`.
fn demo_scene_and_stage1(
    steps: &Steps,
    opts: &DemoOptions,
    data: &Path,
    s1_dir: &Path,
) -> Result<TrainedRun> {
    let (scene, n) = (opts.scene, DEMO_PHASES);
    let size = opts.size.scene(opts.fast);
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
    steps.make_scene(scene, data, &size)?;

    let tsize = opts.size.train(opts.fast);
    phase(
        2,
        n,
        &format!(
            "stage 1: train --stage plenoxels --preset fast{}{} on {} → {}",
            tsize.res.map_or(String::new(), |r| format!(" --res {r}")),
            tsize
                .iters
                .map_or(String::new(), |i| format!(" --iters {i}")),
            steps.backend(),
            s1_dir.display()
        ),
    );
    steps.train_plenoxels(data, s1_dir, &tsize)
}

/// Demo phase 4: stage 2 (αSurf) from `s1` into `s2_dir`. The outer error is a stop asked for
/// by a signal (it ends the demo); the inner one a failed stage 2, which leaves the table its
/// Plenoxels rows.
fn demo_stage2(
    steps: &Steps,
    opts: &DemoOptions,
    s1: &TrainedRun,
    data: &Path,
    s1_dir: &Path,
    s2_dir: &Path,
) -> Result<Result<TrainedRun>> {
    let scene = opts.scene;
    phase(
        4,
        DEMO_PHASES,
        &format!(
            "stage 2 (αSurf): train --stage surface --init {} --category {} → {}",
            s1_dir.display(),
            category(scene),
            s2_dir.display()
        ),
    );
    let stage2 = SurfaceOverrides {
        category: category(scene),
        iters: opts.size.surface_iters(opts.fast),
        set: opts.size.surface_set.clone(),
    };
    // A failed stage 2 leaves the table its Plenoxels rows; a stop asked for by a signal ends
    // the demo.
    let s2 = interrupt::unless_stopped(steps.train_surface(&s1.dir, data, s2_dir, &stage2))?;
    if let Err(e) = &s2 {
        eprintln!("demo: STAGE 2 FAILED — the table shows the Plenoxels rows only.\n  {e:#}");
    }
    Ok(s2)
}

/// First line of a message.
pub fn first_line(s: &str) -> &str {
    s.lines().next().unwrap_or("")
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(super) fn row(method: &str, kind: &str, level: Option<f32>, chamfer: Option<f64>) -> Row {
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
}
