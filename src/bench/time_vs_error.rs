//! `alphasurf bench time-vs-error`: run time against reconstruction error. On one generated scene
//! it trains stage 1 at each sweep point (backend, final grid resolution, steps), sweeps the
//! Plenoxels density levels and keeps the best, trains stage 2 (αSurf) from the same stage-1 run,
//! and for each method records wall time, training rays/s, Chamfer, F1 and test PSNR. All steps
//! are the pipeline's library calls (see `pipeline::steps`). Writes
//! `time_vs_error.csv` and `time_vs_error.png` (Chamfer against wall time), prints a table, and
//! with `--json` one JSON line last.

use crate::backend::Backend;
use crate::pipeline::demo::{
    alphasurf_row, best_plenoxels, category, first_line, plenoxels_levels, Row, SizeArgs, LEVELS,
};
use crate::pipeline::steps::{PlenoxelsOverrides, Steps, SurfaceOverrides};
use crate::pipeline::Devices;
use crate::report::plot::{self, Axis, Plot, Series, Style, PALETTE};
use crate::run::interrupt;
use crate::scene::SceneKind;
use anyhow::{bail, Context, Result};
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// One sweep point: where stage 1 runs, its final grid resolution and its step count.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct SweepPoint {
    pub backend: Backend,
    pub res: u32,
    pub iters: u32,
}

impl SweepPoint {
    /// Parse `BACKEND:RES:ITERS` (backend `cpu` or `vulkan`).
    pub fn parse(s: &str) -> Result<SweepPoint, String> {
        let f: Vec<&str> = s.trim().split(':').collect();
        let [b, r, i] = f[..] else {
            return Err(format!(
                "{s:?}: expected BACKEND:RES:ITERS, e.g. cpu:128:3000"
            ));
        };
        let backend = match b {
            "cpu" => Backend::Cpu,
            "vulkan" => Backend::Vulkan,
            _ => return Err(format!("{s:?}: backend must be cpu or vulkan")),
        };
        let res: u32 = r
            .parse()
            .map_err(|_| format!("{s:?}: bad resolution {r:?}"))?;
        let iters: u32 = i
            .parse()
            .map_err(|_| format!("{s:?}: bad step count {i:?}"))?;
        if !(8..=1024).contains(&res) || iters == 0 {
            return Err(format!("{s:?}: resolution must be 8..=1024 and steps ≥ 1"));
        }
        Ok(SweepPoint {
            backend,
            res,
            iters,
        })
    }

    fn name(&self) -> String {
        format!("{}-{}-{}", self.backend, self.res, self.iters)
    }
}

/// Arguments of `bench time-vs-error`.
#[derive(clap::Args, Debug)]
pub struct TimeVsErrorArgs {
    /// Which built-in scene (generated at 256², 100 views, as in `demo`).
    #[arg(long, value_enum, default_value = "thin")]
    pub scene: SceneKind,
    /// Sweep points BACKEND:RES:ITERS: backend, final grid resolution and stage-1 steps (preset
    /// `fast` otherwise; stage 2 runs half as many steps, as in the preset, on the same backend).
    /// The default sweeps resolution (64³ vs 128³ at 1000 steps), steps (1000 vs 3000 at 128³)
    /// and backend (the CPU twins vs Vulkan at the small 64³/1000 point: lavapipe is slow).
    #[arg(
        long,
        value_delimiter = ',',
        value_parser = SweepPoint::parse,
        default_value = "cpu:64:1000,cpu:128:1000,cpu:128:3000,vulkan:64:1000"
    )]
    pub points: Vec<SweepPoint>,
    /// Skip stage 2 (αSurf) and measure the Plenoxels baseline only.
    #[arg(long)]
    pub no_surface: bool,
    /// Output directory (default: runs/time-vs-error-SCENE).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Print one JSON object with every row as the last stdout line.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub size: SizeArgs,
}

/// One measured method at one sweep point.
#[derive(Clone, Debug, Serialize)]
pub struct BenchRow {
    pub backend: Backend,
    pub res: u32,
    pub iters: u32,
    /// "plenoxels_best" or "alphasurf".
    pub method: String,
    /// Best density level (Plenoxels).
    pub level: Option<f32>,
    /// Training (stage 1, + stage 2 for αSurf) + extraction wall time.
    pub wall_s: f64,
    /// Training rays/s of the last training stage.
    pub train_rays_per_s: Option<f64>,
    pub chamfer_e2: Option<f64>,
    pub f1: Option<f64>,
    pub test_psnr: Option<f64>,
    pub error: Option<String>,
}

impl BenchRow {
    fn from_row(p: &SweepPoint, r: &Row, rays_per_s: Option<f64>) -> BenchRow {
        BenchRow {
            backend: p.backend,
            res: p.res,
            iters: p.iters,
            method: r.kind.clone(),
            level: r.level,
            wall_s: r.wall_s,
            train_rays_per_s: rays_per_s,
            chamfer_e2: r.chamfer_e2,
            f1: r.f1,
            test_psnr: r.test_psnr,
            error: r.error.clone(),
        }
    }

    fn failed(p: &SweepPoint, method: &str, e: String) -> BenchRow {
        BenchRow {
            backend: p.backend,
            res: p.res,
            iters: p.iters,
            method: method.into(),
            level: None,
            wall_s: f64::NAN,
            train_rays_per_s: None,
            chamfer_e2: None,
            f1: None,
            test_psnr: None,
            error: Some(e),
        }
    }
}

/// Text of an optional number ("" when absent), for the CSV.
fn opt(v: Option<f64>, prec: usize) -> String {
    v.filter(|x| x.is_finite())
        .map_or(String::new(), |x| format!("{x:.prec$}"))
}

/// The CSV text of the rows.
pub fn csv(scene: &str, rows: &[BenchRow]) -> String {
    let mut s = String::from(
        "scene,backend,res,iters,method,level,wall_s,train_rays_per_s,chamfer_e2,f1,test_psnr,error\n",
    );
    for r in rows {
        let err = r
            .error
            .as_deref()
            .map(|e| first_line(e).replace([',', '"'], ";"))
            .unwrap_or_default();
        let _ = writeln!(
            s,
            "{scene},{},{},{},{},{},{},{},{},{},{},{}",
            r.backend,
            r.res,
            r.iters,
            r.method,
            r.level.map_or(String::new(), |l| l.to_string()),
            opt(Some(r.wall_s), 2),
            opt(r.train_rays_per_s, 0),
            opt(r.chamfer_e2, 4),
            opt(r.f1, 4),
            opt(r.test_psnr, 2),
            err
        );
    }
    s
}

/// A failure message cut to the last 100 characters of its first line, where the cause is (the
/// CSV and JSON keep it whole).
fn short(e: &str) -> String {
    let l = first_line(e);
    let n = l.chars().count();
    if n <= 100 {
        return l.to_string();
    }
    format!("…{}", l.chars().skip(n - 100).collect::<String>())
}

/// The printed table.
fn table(rows: &[BenchRow]) -> String {
    let mut s = format!(
        "{:<7} {:>4} {:>6}  {:<15} {:>5} {:>9} {:>9} {:>14} {:>7} {:>9}\n",
        "backend",
        "res",
        "steps",
        "method",
        "level",
        "wall s",
        "rays/s",
        "Chamfer ×10⁻²",
        "F1",
        "PSNR dB"
    );
    let f = |v: Option<f64>, p: usize| {
        v.filter(|x| x.is_finite())
            .map_or("—".to_string(), |x| format!("{x:.p$}"))
    };
    for r in rows {
        let _ = writeln!(
            s,
            "{:<7} {:>4} {:>6}  {:<15} {:>5} {:>9} {:>9} {:>14} {:>7} {:>9}{}",
            r.backend,
            r.res,
            r.iters,
            if r.method == "alphasurf" {
                "αSurf"
            } else {
                "Plen (best σ)"
            },
            r.level.map_or("—".to_string(), |l| l.to_string()),
            f(Some(r.wall_s), 1),
            f(r.train_rays_per_s, 0),
            f(r.chamfer_e2, 4),
            f(r.f1, 4),
            f(r.test_psnr, 2),
            r.error
                .as_deref()
                .map_or(String::new(), |e| format!("  failed: {}", short(e)))
        );
    }
    s
}

/// Chamfer against wall time, one series per (method, backend), each point labelled RES/STEPS.
pub fn plot_png(rows: &[BenchRow], path: &Path) -> Result<()> {
    let mut series = Vec::new();
    for (method, label) in [
        ("plenoxels_best", "PLENOXELS (BEST σ)"),
        ("alphasurf", "αSURF"),
    ] {
        for backend in [Backend::Cpu, Backend::Vulkan] {
            let pts: Vec<&BenchRow> = rows
                .iter()
                .filter(|r| r.method == method && r.backend == backend && r.chamfer_e2.is_some())
                .collect();
            if pts.is_empty() {
                continue;
            }
            series.push(Series {
                label: format!("{label} {}", backend.name().to_uppercase()),
                points: pts
                    .iter()
                    .map(|r| (r.wall_s, r.chamfer_e2.unwrap()))
                    .collect(),
                colour: PALETTE[series.len() % PALETTE.len()],
                style: Style::Markers,
                point_labels: pts
                    .iter()
                    .map(|r| format!("{}³/{}", r.res, r.iters))
                    .collect(),
            });
        }
    }
    if series.is_empty() {
        bail!("no sweep point was evaluated; nothing to plot");
    }
    plot::single(
        900,
        560,
        &Plot {
            title: "ERROR VS RUN TIME".into(),
            x: Axis {
                label: "WALL TIME (S): TRAINING + EXTRACTION".into(),
                log: true,
            },
            y: Axis {
                label: "CHAMFER ×0.01".into(),
                log: false,
            },
        },
        &series,
    )
    .save(path)
}

/// Run the benchmark.
pub fn run(args: &TimeVsErrorArgs, devices: &mut Devices) -> Result<()> {
    let t0 = Instant::now();
    if args.points.is_empty() {
        bail!("--points: give at least one sweep point");
    }
    if args.size.grid_res.is_some() || args.size.iters.is_some() {
        bail!("--grid-res/--iters: the sweep points (--points BACKEND:RES:ITERS) set these");
    }
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("runs/time-vs-error-{}", args.scene.name())));
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let cpu = Steps::new(None).quiet();
    // The Vulkan device is opened only when a sweep point asks for it; a device that cannot be
    // opened fails those points, not the others.
    let vk = if args.points.iter().any(|p| p.backend == Backend::Vulkan) {
        devices
            .gpu()
            .map(|g| Steps::new(Some(g)).quiet())
            .map_err(|e| format!("{e:#}"))
    } else {
        Err("no Vulkan sweep point".to_string())
    };
    let data = out.join("scene");
    let size = args.size.scene(false);
    eprintln!(
        "time-vs-error: make-scene --kind {} ({}² images, {} views) → {}",
        args.scene.name(),
        size.image_res,
        size.views,
        data.display()
    );
    cpu.make_scene(args.scene, &data, &size)?;
    let mut rows = Vec::new();
    for (k, p) in args.points.iter().enumerate() {
        let steps = match (p.backend, &vk) {
            (Backend::Vulkan, Ok(vk)) => vk,
            (Backend::Vulkan, Err(e)) => {
                eprintln!("time-vs-error: no Vulkan device: {e}");
                rows.push(BenchRow::failed(p, "plenoxels_best", e.clone()));
                continue;
            }
            _ => &cpu,
        };
        eprintln!(
            "\n=== time-vs-error [{}/{}] {}: stage 1 at {}³, {} steps",
            k + 1,
            args.points.len(),
            p.backend,
            p.res,
            p.iters
        );
        measure_point(steps, args, p, &data, &out.join(p.name()), &mut rows)?;
    }
    write_and_print(args, &out, &rows, t0)?;
    let failed = rows.iter().filter(|r| r.error.is_some()).count();
    super::ensure_any_succeeded("sweep point's method", failed, rows.len())
}

/// One sweep point in `dir`: stage 1 and its best Plenoxels level, then (unless
/// `--no-surface`) stage 2 from the same run; pushes a row per method, a failed one when its
/// training failed. Errs only when a signal asked to stop.
fn measure_point(
    steps: &Steps,
    args: &TimeVsErrorArgs,
    p: &SweepPoint,
    data: &Path,
    dir: &Path,
    rows: &mut Vec<BenchRow>,
) -> Result<()> {
    let gt = data.join("gt_points.ply");
    let tsize = PlenoxelsOverrides {
        res: Some(p.res),
        iters: Some(p.iters),
        batch: args.size.batch,
        set: Vec::new(),
    };
    let s1 = steps.train_plenoxels(data, &dir.join("plenoxels"), &tsize);
    let s1 = match interrupt::unless_stopped(s1)? {
        Ok(s1) => s1,
        Err(e) => {
            eprintln!("time-vs-error: stage 1 failed: {e:#}");
            rows.push(BenchRow::failed(p, "plenoxels_best", format!("{e:#}")));
            return Ok(());
        }
    };
    let levels = plenoxels_levels(steps, &s1, &gt, &LEVELS);
    match best_plenoxels(&levels) {
        Some(b) => rows.push(BenchRow::from_row(p, &b, Some(s1.train_rays_per_s))),
        None => rows.push(BenchRow::failed(
            p,
            "plenoxels_best",
            "no density level gave an evaluable point cloud".into(),
        )),
    }
    if args.no_surface {
        eprintln!("time-vs-error: stage 2 skipped (--no-surface)");
        return Ok(());
    }
    eprintln!("time-vs-error: stage 2 (αSurf) from {}", s1.dir.display());
    let stage2 = SurfaceOverrides {
        category: category(args.scene),
        iters: Some(args.size.surface_iters.unwrap_or((p.iters / 2).max(1))),
        set: args.size.surface_set.clone(),
    };
    let s2 = steps.train_surface(&s1.dir, data, &dir.join("alphasurf"), &stage2);
    match interrupt::unless_stopped(s2)? {
        Ok(s2) => {
            let r = alphasurf_row(steps, &s1, &s2, &gt);
            rows.push(BenchRow::from_row(p, &r, Some(s2.train_rays_per_s)));
        }
        Err(e) => {
            let msg = format!("{e:#}");
            eprintln!("time-vs-error: STAGE 2 FAILED: {msg}");
            rows.push(BenchRow::failed(p, "alphasurf", msg));
        }
    }
    Ok(())
}

/// Writes the CSV and the plot (a plot that fails is reported, not fatal) into `out`, prints
/// the table and what was written, and with `--json` the JSON line.
fn write_and_print(
    args: &TimeVsErrorArgs,
    out: &Path,
    rows: &[BenchRow],
    t0: Instant,
) -> Result<()> {
    let csv_path = out.join("time_vs_error.csv");
    crate::io::atomic::write_bytes(&csv_path, csv(args.scene.name(), rows).as_bytes())?;
    let png_path = out.join("time_vs_error.png");
    let png = plot_png(rows, &png_path);
    if let Err(e) = &png {
        eprintln!("time-vs-error: no plot: {e:#}");
    }
    println!();
    print!("{}", table(rows));
    println!(
        "wrote {}{} in {:.1} s",
        csv_path.display(),
        if png.is_ok() {
            format!(" and {}", png_path.display())
        } else {
            String::new()
        },
        t0.elapsed().as_secs_f64()
    );
    if args.json {
        let j = serde_json::json!({
            "bench": "time-vs-error",
            "scene": args.scene.name(),
            "rows": rows,
            "csv": csv_path,
            "png": png.is_ok().then_some(&png_path),
            "total_s": t0.elapsed().as_secs_f64(),
        });
        println!("{j}");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sweep_points_parse_and_reject() {
        assert_eq!(
            SweepPoint::parse("cpu:128:3000").unwrap(),
            SweepPoint {
                backend: Backend::Cpu,
                res: 128,
                iters: 3000
            }
        );
        assert_eq!(
            SweepPoint::parse(" vulkan:64:5").unwrap().backend,
            Backend::Vulkan
        );
        for bad in [
            "cpu:128",
            "gpu:64:10",
            "cpu:x:10",
            "cpu:4:10",
            "cpu:64:0",
            "",
        ] {
            assert!(SweepPoint::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn csv_has_one_line_per_row_and_no_stray_commas() {
        let p = SweepPoint::parse("cpu:64:10").unwrap();
        let mut r = BenchRow::failed(&p, "alphasurf", "bad, \"thing\"\nmore".into());
        r.wall_s = 1.5;
        let ok = BenchRow {
            chamfer_e2: Some(0.5),
            f1: Some(0.9),
            level: Some(30.0),
            error: None,
            method: "plenoxels_best".into(),
            ..r.clone()
        };
        let text = csv("thin", &[ok, r]);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 3);
        let n = lines[0].split(',').count();
        assert!(lines.iter().all(|l| l.split(',').count() == n), "{text}");
        assert!(
            lines[1].contains(",30,1.50,,0.5000,0.9000,"),
            "{}",
            lines[1]
        );
        assert!(lines[2].ends_with("bad; ;thing;"), "{}", lines[2]);
    }
}
