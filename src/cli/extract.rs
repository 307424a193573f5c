//! `alphasurf extract`: level-set point cloud of a trained grid as binary PLY (method.md §4). For
//! a stage-1 density grid this is the Plenoxels baseline "Plen (σ = τ)": the surfaces σ = τ for
//! each `--levels` value, with no opacity trimming.

use super::train::Backend;
use crate::cpu::extract_points::ExtractInput;
use crate::data::SceneBox;
use crate::eval::extract::{allocated_cells, extract_sorted, to_cloud, ExtractBackend, GridFrame};
use crate::gpu::Gpu;
use crate::grid::{checkpoint, npz, Grid};
use crate::train::stage1;
use anyhow::{ensure, Context, Result};
use serde_json::json;
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `extract`.
#[derive(clap::Args, Debug)]
pub struct ExtractArgs {
    /// A run directory written by `train` (its `plenoxels.npz`).
    #[arg(long, required_unless_present = "ckpt", conflicts_with = "ckpt")]
    pub run: Option<PathBuf>,
    /// An svox2 `ckpt.npz` (or any npz with the svox2 grid arrays) instead of `--run`.
    #[arg(long)]
    pub ckpt: Option<PathBuf>,
    /// Output PLY (binary little-endian: x, y, z, level, alpha, nx, ny, nz; Blender units).
    #[arg(long)]
    pub out: PathBuf,
    /// Level values τ, comma-separated (density units for a stage-1 grid; the paper sweeps
    /// 10,30,50,70,90,100 and reports the best single level).
    #[arg(long, value_delimiter = ',', default_value = "50")]
    pub levels: Vec<f32>,
    /// Keep a crossing only where the trilerped raw opacity σα ≥ this (stage-2 grids; a stage-1
    /// density grid has no opacity field, so it is not used there).
    #[arg(long, default_value_t = 0.1)]
    pub min_alpha: f32,
    /// R: R² virtual rays per axis and cell (origins on the lattice 0, 1/(R−1), …, 1).
    #[arg(long, default_value_t = 5)]
    pub rays_per_axis: u32,
    #[arg(long, value_enum, default_value = "auto")]
    pub backend: Backend,
    /// Thinning radius in Blender units (per level, then on the union); 0 keeps every point.
    #[arg(long, default_value_t = 0.001)]
    pub thin_radius: f64,
    /// Blender → grid-scene scale (default: the scene box's, 2/3).
    #[arg(long)]
    pub scene_scale: Option<f32>,
    /// Initial capacity of the device point buffer (default: min(upper bound, 2²¹) points).
    #[arg(long, hide = true)]
    pub capacity: Option<usize>,
    /// Print one JSON object with the counts and timings as the last stdout line.
    #[arg(long)]
    pub json: bool,
}

/// Load the grid named by `--run` or `--ckpt`.
fn load_grid(args: &ExtractArgs) -> Result<(Grid, PathBuf)> {
    if let Some(ckpt) = &args.ckpt {
        return Ok((npz::load_svox2(ckpt)?, ckpt.clone()));
    }
    let run = args.run.as_ref().context("give --run or --ckpt")?;
    let path = stage1::checkpoint_path(run);
    ensure!(
        path.exists(),
        "{}: no {} (is this a run directory written by `alphasurf train`?)",
        run.display(),
        stage1::CHECKPOINT
    );
    Ok((checkpoint::load(&path)?.grid, path))
}

/// Run the command.
pub fn run(args: &ExtractArgs, gpu: Option<&Gpu>) -> Result<()> {
    let t0 = Instant::now();
    ensure!(!args.levels.is_empty(), "--levels: give at least one level");
    ensure!(
        args.levels.iter().all(|l| l.is_finite()),
        "--levels: every level must be finite, got {:?}",
        args.levels
    );
    ensure!(
        (1..=64).contains(&args.rays_per_axis),
        "--rays-per-axis must be in 1..=64, got {}",
        args.rays_per_axis
    );
    ensure!(
        args.thin_radius >= 0.0 && args.thin_radius.is_finite(),
        "--thin-radius must be ≥ 0"
    );
    let scene_scale = args.scene_scale.unwrap_or(SceneBox::default().scale);
    ensure!(
        scene_scale > 0.0 && scene_scale.is_finite(),
        "--scene-scale must be positive"
    );
    let (grid, path) = load_grid(args)?;
    let t_load = t0.elapsed().as_secs_f64() * 1e3;
    let cells = allocated_cells(grid.res, &grid.links)?;
    println!(
        "grid {} : {:?} vertices, {} allocated, {} cells with 8 allocated corners",
        path.display(),
        grid.res,
        grid.allocated(),
        cells.len()
    );
    println!(
        "density levels {:?} (Plen σ = τ; no opacity field, --min-alpha {} not used)",
        args.levels, args.min_alpha
    );
    let inp = ExtractInput {
        cells: &cells,
        links: &grid.links,
        field: &grid.density,
        opacity: None,
        levels: &args.levels,
        res: grid.res,
        rays_per_axis: args.rays_per_axis,
        min_opacity: args.min_alpha,
    };
    let backend = match gpu {
        Some(g) => ExtractBackend::Vulkan(g),
        None => ExtractBackend::Cpu,
    };
    let (points, kstats) = extract_sorted(backend, &inp, args.capacity)?;
    if kstats.retries > 0 {
        println!(
            "point buffer was full: ran the kernel {} more time(s) with room for {} points",
            kstats.retries, kstats.capacity
        );
    }
    let frame = GridFrame {
        res: grid.res,
        center: grid.center,
        radius: grid.radius,
        scene_scale,
    };
    let (cloud, tstats) = to_cloud(&points, &args.levels, &frame, args.thin_radius)?;
    ensure!(
        !cloud.points.is_empty(),
        "no surface points at levels {:?} (density range {:?}); nothing written",
        args.levels,
        density_range(&grid)
    );
    let t_w = Instant::now();
    crate::io::write_ply(&args.out, &cloud)?;
    let write_ms = t_w.elapsed().as_secs_f64() * 1e3;
    let backend_name = match backend {
        ExtractBackend::Vulkan(g) => g.info().name.clone(),
        ExtractBackend::Cpu => "cpu".to_string(),
    };
    println!(
        "{}² rays per axis and cell on {}: {} raw points in {:.1} ms (kernel {:.1} ms device)",
        args.rays_per_axis, backend_name, kstats.points, kstats.wall_ms, kstats.device_ms
    );
    for (l, n) in args.levels.iter().zip(&tstats.per_level) {
        println!("  level {l:>8}: {n:>9} points");
    }
    println!(
        "thinned (radius {}) to {} points in {:.1} ms; wrote {} in {:.1} ms; total {:.2} s (load {:.0} ms)",
        args.thin_radius,
        tstats.kept,
        tstats.wall_ms,
        args.out.display(),
        write_ms,
        t0.elapsed().as_secs_f64(),
        t_load
    );
    if args.json {
        let j = json!({
            "out": args.out,
            "grid": path,
            "res": grid.res,
            "levels": args.levels,
            "rays_per_axis": args.rays_per_axis,
            "backend": backend_name,
            "kernel": kstats,
            "thin": tstats,
            "points": cloud.points.len(),
            "total_s": t0.elapsed().as_secs_f64(),
        });
        println!("{j}");
    }
    Ok(())
}

/// (min, max) of the density over the allocated vertices.
fn density_range(grid: &Grid) -> (f32, f32) {
    grid.density
        .iter()
        .fold((f32::MAX, f32::MIN), |(a, b), &x| (a.min(x), b.max(x)))
}
