//! `alphasurf eval`: Chamfer distance and F-score of a predicted point cloud against the ground
//! truth (method.md §4), both read from PLY. Both clouds are first thinned with `--downsample`
//! (the paper downsamples predicted and GT points at 0.001); an extraction is already thinned at
//! that radius, so this only changes an unthinned cloud.

use crate::eval::{evaluate, thin, EvalOptions};
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
    /// Print one JSON object with every figure as the last stdout line.
    #[arg(long)]
    pub json: bool,
}

/// Read a cloud and thin it; returns (points, count before thinning).
fn load(path: &Path, radius: f64) -> Result<(Vec<[f32; 3]>, usize)> {
    let pts = read_points(path)?;
    let n = pts.len();
    let kept = thin(&pts, radius)?;
    Ok((kept.into_iter().map(|i| pts[i]).collect(), n))
}

/// Run the command.
pub fn run(args: &EvalArgs) -> Result<()> {
    ensure!(
        args.max_dist > 0.0 && args.threshold > 0.0 && args.downsample >= 0.0,
        "--max-dist and --threshold must be positive, --downsample ≥ 0"
    );
    let t0 = Instant::now();
    let (pred, gt) = rayon::join(
        || load(&args.pred, args.downsample),
        || load(&args.gt, args.downsample),
    );
    let ((pred, n_pred_raw), (gt, n_gt_raw)) = (pred?, gt?);
    let t_load = t0.elapsed().as_secs_f64();
    let opts = EvalOptions {
        max_dist: args.max_dist,
        threshold: args.threshold,
    };
    let t1 = Instant::now();
    let m = evaluate(&pred, &gt, &opts)?;
    let t_eval = t1.elapsed().as_secs_f64();
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
    Ok(())
}
