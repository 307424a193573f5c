//! `alphasurf extract`: level-set point cloud of a trained grid as binary PLY (method.md §4). For
//! a stage-2 run (surface.npz) these are the αSurf surfaces δ = τ_i at the run's levels, trimmed
//! by raw opacity σα ≥ `--min-alpha`. For a stage-1 density grid this is the Plenoxels baseline
//! "Plen (σ = τ)": the surfaces σ = τ for each `--levels` value, with no opacity trimming.

use crate::backend::Backend;
use crate::cpu::extract_points::ExtractInput;
use crate::data::SceneBox;
use crate::eval::extract::{allocated_cells, extract_sorted, to_cloud, ExtractBackend, GridFrame};
use crate::gpu::Gpu;
use crate::grid::surface::SurfaceGrid;
use crate::grid::{checkpoint, npz, Grid};
use crate::train::{stage1, stage2};
use anyhow::{ensure, Context, Result};
use serde_json::json;
use std::path::PathBuf;
use std::time::Instant;

/// Virtual rays per axis and cell face by default: method.md's 75 rays per cell (5 × 5 per axis).
pub const DEFAULT_RAYS_PER_AXIS: u32 = 5;

/// Arguments of `extract`.
#[derive(clap::Args, Debug)]
pub struct ExtractArgs {
    /// A run directory written by `train`: its `surface.npz` (stage 2) if there is one, else its
    /// `plenoxels.npz` (stage 1).
    #[arg(long, required_unless_present = "ckpt", conflicts_with = "ckpt")]
    pub run: Option<PathBuf>,
    /// An svox2 `ckpt.npz` (or any npz with the svox2 grid arrays) instead of `--run`.
    #[arg(long)]
    pub ckpt: Option<PathBuf>,
    /// Output PLY (binary little-endian: x, y, z, level, alpha, nx, ny, nz; Blender units).
    #[arg(long)]
    pub out: PathBuf,
    /// Level values τ, comma-separated, for a stage-1 grid (density units; the paper sweeps
    /// 10,30,50,70,90,100 and reports the best single level). Default 50. A stage-2 run uses its
    /// own levels; giving --levels there is an error.
    #[arg(long, value_delimiter = ',')]
    pub levels: Option<Vec<f32>>,
    /// Keep a crossing only where the trilerped raw opacity σα ≥ this (stage-2 grids; a stage-1
    /// density grid has no opacity field, so it is not used there).
    #[arg(long, default_value_t = 0.1)]
    pub min_alpha: f32,
    /// R: R² virtual rays per axis and cell (origins on the lattice 0, 1/(R−1), …, 1).
    #[arg(long, default_value_t = DEFAULT_RAYS_PER_AXIS)]
    pub rays_per_axis: u32,
    /// Where the kernels run.
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
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

/// The field to extract: a stage-1 density grid, or a stage-2 surface grid.
enum Field {
    Density(Grid),
    Surface(SurfaceGrid),
}

/// Load the grid named by `--run` or `--ckpt`.
fn load_grid(args: &ExtractArgs) -> Result<(Field, PathBuf)> {
    if let Some(ckpt) = &args.ckpt {
        return Ok((Field::Density(npz::load_svox2(ckpt)?), ckpt.clone()));
    }
    let run = args.run.as_ref().context("give --run or --ckpt")?;
    let surface = stage2::checkpoint_path(run);
    if surface.exists() {
        return Ok((Field::Surface(SurfaceGrid::load(&surface)?.grid), surface));
    }
    let path = stage1::checkpoint_path(run);
    ensure!(
        path.exists(),
        "{}: no {} (is this a run directory written by `alphasurf train`?)",
        run.display(),
        stage1::CHECKPOINT
    );
    Ok((Field::Density(checkpoint::load(&path)?.grid), path))
}

/// Run the command.
pub fn run(args: &ExtractArgs, gpu: Option<&Gpu>) -> Result<()> {
    let t0 = Instant::now();

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
    ensure!(
        args.min_alpha.is_finite(),
        "--min-alpha must be a finite number, got {}",
        args.min_alpha
    );
    let (field, path) = load_grid(args)?;
    crate::run::outputs::check_output_file(&args.out, &[&path])?;
    let t_load = t0.elapsed().as_secs_f64() * 1e3;
    let (res, center, radius, links) = match &field {
        Field::Density(g) => (g.res, g.center, g.radius, &g.links),
        Field::Surface(g) => (g.res, g.center, g.radius, &g.links),
    };
    let cells = allocated_cells(res, links)?;
    let (values, opacity, levels) = match &field {
        Field::Density(g) => {
            let levels = args.levels.clone().unwrap_or(vec![50.0]);
            println!(
                "density levels {levels:?} (Plen σ = τ; no opacity field, --min-alpha {} not used)",
                args.min_alpha
            );
            (&g.density, None, levels)
        }
        Field::Surface(g) => {
            ensure!(
                args.levels.is_none(),
                "--levels applies to stage-1 grids; {} has its own levels {:?}",
                path.display(),
                g.levels
            );
            println!(
                "αSurf levels τ = {:?} (δ units), kept where σα ≥ {}",
                g.levels, args.min_alpha
            );
            (&g.delta, Some(g.opacity.as_slice()), g.levels.clone())
        }
    };
    ensure!(!levels.is_empty(), "--levels: give at least one level");
    ensure!(
        levels.iter().all(|l| l.is_finite()),
        "--levels: every level must be finite, got {levels:?}"
    );
    println!(
        "grid {} : {:?} vertices, {} allocated, {} cells with 8 allocated corners",
        path.display(),
        res,
        values.len(),
        cells.len()
    );
    let inp = ExtractInput {
        cells: &cells,
        links,
        field: values,
        opacity,
        levels: &levels,
        res,
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
        res,
        center,
        radius,
        scene_scale,
    };
    let (cloud, tstats) = to_cloud(&points, &levels, &frame, args.thin_radius)?;
    ensure!(
        !cloud.points.is_empty(),
        "no surface points at levels {levels:?} (field range {:?}); nothing written",
        value_range(values)
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
    for (l, n) in levels.iter().zip(&tstats.per_level) {
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
            "res": res,
            "levels": levels,
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

/// (min, max) of the field over the allocated vertices.
fn value_range(v: &[f32]) -> (f32, f32) {
    v.iter()
        .fold((f32::MAX, f32::MIN), |(a, b), &x| (a.min(x), b.max(x)))
}
