//! `extract`: the library call and what it prints (levels, counts per level, timings, `--json`).

use crate::eval::hidden::HiddenStats;
use crate::gpu::Gpu;
use crate::pipeline::extract::{extract, ExtractOptions, MeshReport, PointsReport};
use anyhow::Result;
use serde_json::json;

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
    let mut j = json!({
        "grid": r.grid,
        "res": r.res,
        "levels": r.levels,
    });
    if let Some(p) = &r.points {
        print_points(p, &r.levels);
        j["out"] = json!(p.out);
        j["rays_per_axis"] = json!(p.rays_per_axis);
        j["backend"] = json!(p.backend);
        j["kernel"] = json!(p.kernel);
        j["hidden"] = json!(p.hidden);
        j["outer_dropped"] = json!(p.outer_dropped);
        j["sheets_moved"] = json!(p.sheets_moved);
        j["thin"] = json!(p.thin);
        j["points"] = json!(p.points);
    }
    if let Some(m) = &r.mesh {
        print_mesh(m, &r.levels);
        j["mesh"] = json!(m.out);
        j["mesh_stats"] = json!(m.stats);
        j["mesh_hidden"] = json!(m.hidden);
        j["mesh_outer_dropped"] = json!(m.outer_dropped);
    }
    println!("total {:.2} s (load {:.0} ms)", r.total_s, r.load_ms);
    if opts.json {
        j["total_s"] = json!(r.total_s);
        println!("{j}");
    }
    Ok(())
}

fn print_points(p: &PointsReport, levels: &[f32]) {
    if p.kernel.retries > 0 {
        println!(
            "point buffer was full: ran the kernel {} more time(s) with room for {} points",
            p.kernel.retries, p.kernel.capacity
        );
    }
    println!(
        "{}² rays per axis and cell on {}: {} raw points in {:.1} ms (kernel {:.1} ms device)",
        p.rays_per_axis, p.backend, p.kernel.points, p.kernel.wall_ms, p.kernel.device_ms
    );
    if let Some(h) = &p.hidden {
        print_hidden(h, "points");
    }
    if let Some(n) = p.outer_dropped {
        println!(
            "outermost level: {n} points dropped around parts thick enough for a higher level"
        );
    }
    if let Some(n) = p.sheets_moved {
        println!("thin sheets: {n} points moved onto the sheet's middle");
    }
    for (l, n) in levels.iter().zip(&p.thin.per_level) {
        println!("  level {l:>8}: {n:>9} points");
    }
    println!(
        "thinned (radius {}) to {} points in {:.1} ms; wrote {} in {:.1} ms",
        p.thin_radius,
        p.thin.kept,
        p.thin.wall_ms,
        p.out.display(),
        p.write_ms,
    );
}

/// The hidden-surface trimming's counts (cells holding `what`).
fn print_hidden(h: &HiddenStats, what: &str) {
    println!(
        "hidden surfaces: of {} cells with {what}, {} seen by a training camera, {} unseen but \
         open, {} hidden (enclosed, dropped) in {:.0} ms",
        h.cells, h.seen, h.open, h.hidden, h.wall_ms
    );
}

fn print_mesh(m: &MeshReport, levels: &[f32]) {
    if let Some(h) = &m.hidden {
        print_hidden(h, "faces");
    }
    if let Some(n) = m.outer_dropped {
        println!("outermost level: {n} faces dropped around parts thick enough for a higher level");
    }
    println!(
        "mesh (marching tetrahedra, on the cpu): {} vertices, {} faces, area {:.4} in {:.1} ms; \
         wrote {} in {:.1} ms",
        m.stats.vertices,
        m.stats.faces,
        m.stats.area,
        m.stats.wall_ms,
        m.out.display(),
        m.write_ms
    );
    for (l, n) in levels.iter().zip(&m.stats.per_level) {
        println!("  level {l:>8}: {n:>9} faces");
    }
}
