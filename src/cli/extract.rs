//! `extract`: the library call and what it prints (levels, counts per level, timings, `--json`).

use crate::gpu::Gpu;
use crate::pipeline::extract::{extract, ExtractOptions};
use anyhow::Result;

/// Run `extract` and print what it did.
pub fn run(opts: &ExtractOptions, gpu: Option<&Gpu>) -> Result<()> {
    let r = extract(opts, gpu)?;
    if r.surface {
        println!(
            "αSurf levels τ = {:?} (δ units), kept where σα ≥ {}",
            r.levels, r.min_alpha
        );
    } else {
        println!(
            "density levels {:?} (Plen σ = τ; no opacity field, --min-alpha {} not used)",
            r.levels, r.min_alpha
        );
    }
    println!(
        "grid {} : {:?} vertices, {} allocated, {} cells with 8 allocated corners",
        r.grid.display(),
        r.res,
        r.vertices,
        r.cells
    );
    if r.kernel.retries > 0 {
        println!(
            "point buffer was full: ran the kernel {} more time(s) with room for {} points",
            r.kernel.retries, r.kernel.capacity
        );
    }
    println!(
        "{}² rays per axis and cell on {}: {} raw points in {:.1} ms (kernel {:.1} ms device)",
        r.rays_per_axis, r.backend, r.kernel.points, r.kernel.wall_ms, r.kernel.device_ms
    );
    for (l, n) in r.levels.iter().zip(&r.thin.per_level) {
        println!("  level {l:>8}: {n:>9} points");
    }
    println!(
        "thinned (radius {}) to {} points in {:.1} ms; wrote {} in {:.1} ms; total {:.2} s (load {:.0} ms)",
        r.thin_radius,
        r.thin.kept,
        r.thin.wall_ms,
        r.out.display(),
        r.write_ms,
        r.total_s,
        r.load_ms
    );
    if opts.json {
        let j = serde_json::json!({
            "out": r.out,
            "grid": r.grid,
            "res": r.res,
            "levels": r.levels,
            "rays_per_axis": r.rays_per_axis,
            "backend": r.backend,
            "kernel": r.kernel,
            "thin": r.thin,
            "points": r.points,
            "total_s": r.total_s,
        });
        println!("{j}");
    }
    Ok(())
}
