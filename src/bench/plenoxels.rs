//! `alphasurf bench plenoxels`: stage-1 training throughput on both backends from the same
//! partly trained grid. A built-in thin scene is generated (small images, so this stays quick),
//! a short fast-preset run on the Vulkan backend brings the grid to `--res`³ with realistic
//! sparsity, then each backend trains the same `--steps` batches from that state. Reported:
//! training rays/s (forward + backward + TV + optimiser, wall time, after one warm-up step), their
//! ratio, device time per kernel (timestamp queries), samples per ray shaded / evaluated empty /
//! skipped by the occupancy volume, and gradient atomic adds per ray; per step, the wall time of
//! the loop iteration, the device time and the host time by phase (`StepFigures`).

use super::stage1::{thin_scene, time_steps, warm_config, StepFigures};
use crate::gpu::Gpu;
use crate::plenoxel::{CpuPlenoxels, VulkanPlenoxels};
use crate::stage::StageBackend;
use crate::train::plenoxels_steps;
use anyhow::{ensure, Result};
use serde_json::json;

/// Arguments of `bench plenoxels`.
#[derive(clap::Args, Debug)]
pub struct PlenoxelsBenchArgs {
    /// Print one JSON object with the figures as the last stdout line.
    #[arg(long)]
    pub json: bool,
    /// Grid resolution of the timed steps.
    #[arg(long, default_value_t = 128)]
    pub res: u32,
    /// Fast-preset steps that prepare the grid before timing.
    #[arg(long, default_value_t = 300)]
    pub warm_steps: u32,
    /// Timed steps per backend.
    #[arg(long, default_value_t = 20)]
    pub steps: u32,
    /// Rays per batch.
    #[arg(long, default_value_t = 4096)]
    pub batch: u32,
}

/// Run the benchmark and print it.
pub fn run(gpu: &Gpu, args: &PlenoxelsBenchArgs) -> Result<()> {
    ensure!((16..=512).contains(&args.res), "--res must be in 16..=512");
    ensure!(
        args.steps >= 1 && args.batch >= 1,
        "--steps and --batch must be at least 1"
    );
    let dir = tempfile_dir()?;
    eprintln!(
        "bench plenoxels: generating the thin scene (128², 40 views) in {}",
        dir.display()
    );
    let data = thin_scene(&dir.join("scene"))?;
    let (cfg, grid0) = warm_config(args.res, args.warm_steps);
    let mut vk = VulkanPlenoxels::new(gpu, grid0)?;
    eprintln!(
        "bench plenoxels: {} warm-up steps to reach a {}³ grid",
        cfg.iters, args.res
    );
    plenoxels_steps::train(&mut vk, &data, &cfg, &dir.join("warm"), 0, false)?;
    let grid = vk.grid()?;

    let before: Vec<(&str, u64, f64)> = gpu.profile().totals();
    let mut vk = VulkanPlenoxels::new(gpu, grid.clone())?;
    let fv = time_steps(&mut vk, &data, &cfg, args.steps, args.batch)?;
    let kernels: Vec<(String, f64)> = gpu
        .profile()
        .totals()
        .into_iter()
        .map(|(k, n, ns)| {
            let prev = before
                .iter()
                .find(|b| b.0 == k)
                .map_or((0, 0.0), |b| (b.1, b.2));
            (k.to_string(), n - prev.0, ns - prev.1)
        })
        .filter(|(_, n, _)| *n > 0)
        .map(|(k, _, ns)| (k, ns / 1e6 / (args.steps + 1) as f64))
        .collect();
    let mut cpu = CpuPlenoxels::new(grid.clone());
    let fc = time_steps(&mut cpu, &data, &cfg, args.steps, args.batch)?;
    let _ = std::fs::remove_dir_all(&dir);

    println!(
        "stage-1 training at {}³ ({} allocated vertices), {} steps of {} rays, thin scene",
        args.res,
        grid.allocated(),
        args.steps,
        args.batch
    );
    println!(
        "{:<8} {:>12} {:>10} {:>9} {:>9} {:>9} {:>12}",
        "backend", "rays/s", "mse", "shaded", "empty", "skipped", "atomics/ray"
    );
    for (name, f) in [("vulkan", &fv), ("cpu", &fc)] {
        println!(
            "{name:<8} {:>12.0} {:>10.5} {:>9.2} {:>9.2} {:>9.2} {:>12.1}",
            f.rays_per_s,
            f.mean_mse,
            f.per_ray.shaded,
            f.per_ray.empty,
            f.per_ray.skipped,
            f.per_ray.atomic_adds
        );
    }
    let ratio = fv.rays_per_s / fc.rays_per_s;
    println!("vulkan / cpu: {ratio:.2}×");
    println!("ms per step: wall, device (kernels' timestamps; the CPU: its compute), host phases:");
    println!("{}", StepFigures::header("backend", 8));
    for (name, f) in [("vulkan", &fv), ("cpu", &fc)] {
        println!("{name:<8} {}", f.times.row());
    }
    println!("device ms per step (Vulkan):");
    for (k, ms) in &kernels {
        println!("  {k:<18} {ms:>9.3}");
    }
    if args.json {
        println!(
            "{}",
            json!({
                "bench": "plenoxels",
                "device": gpu.info().name,
                "res": args.res,
                "allocated_vertices": grid.allocated(),
                "batch": args.batch,
                "steps": args.steps,
                "vulkan": fv,
                "cpu": fc,
                "ratio_vulkan_over_cpu": ratio,
                "device_ms_per_step": kernels.iter().map(|(k, ms)| (k.clone(), json!(ms))).collect::<serde_json::Map<_, _>>(),
            })
        );
    }
    Ok(())
}

/// A fresh scratch directory under the system temp dir.
fn tempfile_dir() -> Result<std::path::PathBuf> {
    let dir = std::env::temp_dir().join(format!("alphasurf-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    Ok(dir)
}
