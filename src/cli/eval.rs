//! `alphasurf eval`: Chamfer distance and F-score of a predicted point cloud against the ground
//! truth (method.md §4), both read from PLY. Both clouds are first thinned with `--downsample`
//! (the paper downsamples predicted and GT points at 0.001); an extraction is already thinned at
//! that radius, so this only changes an unthinned cloud. With the scene's `scene.json` (found next
//! to the GT cloud, or `--scene`) the figures are also split over its objects
//! ([`crate::eval::objects`]).

use crate::eval::objects::{load_groups, GtGroups};
use crate::eval::{evaluate_groups, thin, EvalOptions, Metrics};
use crate::io::read_points;
use anyhow::{ensure, Result};
use serde_json::json;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `eval`.
#[derive(clap::Args, Debug)]
pub struct EvalArgs {
    /// Predicted points (PLY, e.g. from `extract`), Blender units.
    #[arg(long)]
    pub pred: PathBuf,
    /// Ground-truth points (PLY, e.g. a scene's gt_points.ply), Blender units.
    #[arg(long)]
    pub gt: PathBuf,
    /// Distances at or above this are left out of the Chamfer means.
    #[arg(long, default_value_t = 1.5)]
    pub max_dist: f64,
    /// Precision/recall distance threshold.
    #[arg(long, default_value_t = 0.01)]
    pub threshold: f64,
    /// Thin both clouds with this radius before measuring; 0 = off.
    #[arg(long, default_value_t = 0.001)]
    pub downsample: f64,
    /// The scene's scene.json (objects and their GT point ranges, as `make-scene` writes it): split
    /// the figures over its objects. Default: the scene.json next to --gt, when there is one.
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Print one JSON object with every figure as the last stdout line.
    #[arg(long)]
    pub json: bool,
}

/// Read a cloud and thin it; returns (points, indices kept, count before thinning).
fn load(path: &Path, radius: f64) -> Result<(Vec<[f32; 3]>, Vec<usize>, usize)> {
    let pts = read_points(path)?;
    let n = pts.len();
    let kept = thin(&pts, radius)?;
    Ok((kept.iter().map(|&i| pts[i]).collect(), kept, n))
}

/// The GT cloud's object groups: their names, the group of each kept GT point, and the scene.json
/// they came from.
struct ObjectSplit {
    names: Vec<String>,
    labels: Vec<u32>,
    path: PathBuf,
}

/// The object groups from `--scene` (an error there is the command's error), else from a
/// scene.json next to the GT cloud (a problem there is reported and the split skipped).
fn groups(args: &EvalArgs, n_gt: usize, kept: &[usize]) -> Result<Option<ObjectSplit>> {
    let (path, explicit) = match &args.scene {
        Some(p) => (p.clone(), true),
        None => (args.gt.with_file_name("scene.json"), false),
    };
    if !explicit && !path.is_file() {
        return Ok(None);
    }
    match load_groups(&path, n_gt) {
        Ok(GtGroups { names, of_point }) => {
            let labels = kept.iter().map(|&i| of_point[i]).collect();
            Ok(Some(ObjectSplit {
                names,
                labels,
                path,
            }))
        }
        Err(e) if !explicit => {
            println!("no split over objects: {e:#}");
            Ok(None)
        }
        Err(e) => Err(e),
    }
}

/// The per-group table, largest share of the Chamfer distance first.
fn print_groups(m: &Metrics, scene: &str) {
    let mut rows: Vec<_> = m.objects.iter().collect();
    rows.sort_by(|a, b| b.chamfer_share.total_cmp(&a.chamfer_share));
    println!("per object group ({scene}; ×10⁻², the shares add up to the Chamfer distance):");
    println!(
        "  {:<16} {:>9} {:>9} {:>9} {:>9} {:>9}",
        "group", "GT pts", "pred pts", "mean s2d", "mean d2s", "share"
    );
    for g in rows {
        println!(
            "  {:<16} {:>9} {:>9} {:>9.4} {:>9.4} {:>9.4}",
            g.name,
            g.n_gt,
            g.n_pred,
            g.mean_s2d * 100.0,
            g.mean_d2s * 100.0,
            g.chamfer_share * 100.0
        );
    }
}

/// Run the command; returns the metrics it printed (for `demo` and `bench time-vs-error`).
pub fn run(args: &EvalArgs) -> Result<Metrics> {
    ensure!(
        args.max_dist > 0.0 && args.threshold > 0.0 && args.downsample >= 0.0,
        "--max-dist and --threshold must be positive, --downsample ≥ 0"
    );
    let t0 = Instant::now();
    let (pred, gt) = rayon::join(
        || load(&args.pred, args.downsample),
        || load(&args.gt, args.downsample),
    );
    let ((pred, _, n_pred_raw), (gt, gt_kept, n_gt_raw)) = (pred?, gt?);
    let groups = groups(args, n_gt_raw, &gt_kept)?;
    let t_load = t0.elapsed().as_secs_f64();
    let opts = EvalOptions {
        max_dist: args.max_dist,
        threshold: args.threshold,
    };
    let t1 = Instant::now();
    let m = evaluate_groups(
        &pred,
        &gt,
        groups
            .as_ref()
            .map(|g| (g.names.as_slice(), g.labels.as_slice())),
        &opts,
    )?;
    let t_eval = t1.elapsed().as_secs_f64();
    ensure!(
        m.d2s_used > 0 && m.s2d_used > 0,
        "no usable distance: {} of {} predicted and {} of {} ground-truth points lie within \
         --max-dist {} of the other cloud, so the Chamfer distance is undefined (are both clouds \
         in Blender units? a cloud in millimetres is 1000× too large)",
        m.d2s_used,
        m.n_pred,
        m.s2d_used,
        m.n_gt,
        args.max_dist
    );
    println!(
        "pred {}: {} points ({} after downsampling at {})",
        args.pred.display(),
        n_pred_raw,
        m.n_pred,
        args.downsample
    );
    println!(
        "gt   {}: {} points ({} after downsampling)",
        args.gt.display(),
        n_gt_raw,
        m.n_gt
    );
    println!("{:<26} {:>12} {:>12}", "metric", "value", "×10⁻²");
    let row = |name: &str, v: f64| println!("{name:<26} {v:>12.6} {:>12.4}", v * 100.0);
    row("mean d2s (pred → gt)", m.mean_d2s);
    row("mean s2d (gt → pred)", m.mean_s2d);
    row("Chamfer", m.chamfer);
    println!(
        "{:<26} {:>12.4}",
        format!("precision @ {}", args.threshold),
        m.precision
    );
    println!(
        "{:<26} {:>12.4}",
        format!("recall @ {}", args.threshold),
        m.recall
    );
    println!("{:<26} {:>12.4}", "F1", m.f1);
    for (name, q) in [("d2s", m.d2s_quantiles), ("s2d", m.s2d_quantiles)] {
        println!(
            "{name} median / p90 / p99 ×10⁻²: {:.4} / {:.4} / {:.4}",
            q[0] * 100.0,
            q[1] * 100.0,
            q[2] * 100.0
        );
    }
    if let Some(g) = &groups {
        print_groups(&m, &g.path.display().to_string());
    }
    println!(
        "(means over distances < {}: {} of {} pred, {} of {} gt; read+thin {:.2} s, NN {:.2} s)",
        args.max_dist, m.d2s_used, m.n_pred, m.s2d_used, m.n_gt, t_load, t_eval
    );
    if args.json {
        let j = json!({
            "pred": args.pred,
            "gt": args.gt,
            "n_pred_raw": n_pred_raw,
            "n_gt_raw": n_gt_raw,
            "downsample": args.downsample,
            "chamfer_e2": m.chamfer * 100.0,
            "metrics": m,
            "load_s": t_load,
            "nn_s": t_eval,
        });
        println!("{j}");
    }
    Ok(m)
}
