//! `eval`: the library call and what it prints (the figures, each object group's share of the
//! Chamfer distance, `--json`).

use crate::eval::Metrics;
use crate::pipeline::evaluate::{evaluate, EvaluateOptions};
use anyhow::Result;
use serde_json::json;

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

/// Run `eval` and print the figures.
pub fn run(opts: &EvaluateOptions) -> Result<()> {
    let e = evaluate(opts)?;
    if let Some(note) = &e.note {
        println!("{note}");
    }
    for (path, faces) in [(&opts.pred, e.pred_mesh_faces), (&opts.gt, e.gt_mesh_faces)] {
        if let Some(f) = faces {
            println!(
                "{}: a mesh of {f} faces; drew {} points on it",
                path.display(),
                opts.mesh_samples
            );
        }
    }
    let m = &e.metrics;
    println!(
        "pred {}: {} points ({} after downsampling at {}{})",
        opts.pred.display(),
        e.n_pred_raw,
        m.n_pred,
        opts.downsample,
        match &e.scored_box {
            Some((b, outside)) => format!(
                "; {outside} more outside the evaluation box {} from {}, not scored",
                b.bounds, b.from
            ),
            None => String::new(),
        }
    );
    println!(
        "gt   {}: {} points ({} after downsampling{})",
        opts.gt.display(),
        e.n_gt_raw,
        m.n_gt,
        match &e.visible {
            Some((mask, _)) => format!(
                " that {} marks: completeness counts only these",
                mask.display()
            ),
            None => String::new(),
        }
    );
    println!("{:<26} {:>12} {:>12}", "metric", "value", "×10⁻²");
    let row = |name: &str, v: f64| println!("{name:<26} {v:>12.6} {:>12.4}", v * 100.0);
    row("mean d2s (pred → gt)", m.mean_d2s);
    row("mean s2d (gt → pred)", m.mean_s2d);
    row("Chamfer", m.chamfer);
    println!(
        "{:<26} {:>12.4}",
        format!("precision @ {}", opts.threshold),
        m.precision
    );
    println!(
        "{:<26} {:>12.4}",
        format!("recall @ {}", opts.threshold),
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
    if let Some(path) = &e.objects_from {
        print_groups(m, &path.display().to_string());
    }
    println!(
        "(means over distances < {}: {} of {} pred, {} of {} gt; read+thin {:.2} s, NN {:.2} s)",
        opts.max_dist, m.d2s_used, m.n_pred, m.s2d_used, m.n_gt, e.load_s, e.nn_s
    );
    if opts.json {
        let j = json!({
            "pred": opts.pred,
            "gt": opts.gt,
            "n_pred_raw": e.n_pred_raw,
            "n_gt_raw": e.n_gt_raw,
            "downsample": opts.downsample,
            "chamfer_e2": m.chamfer * 100.0,
            "eval_box": e.scored_box.as_ref().map(|(b, outside)| json!({
                "bounds": b.bounds, "from": b.from, "pred_outside": outside,
            })),
            "visible": e.visible.as_ref().map(|(mask, n)| json!({"mask": mask, "gt_scored": n})),
            "metrics": m,
            "load_s": e.load_s,
            "nn_s": e.nn_s,
        });
        println!("{j}");
    }
    Ok(())
}
