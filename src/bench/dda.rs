//! `alphasurf bench dda`: DDA cell-walk throughput on the Vulkan device and on the CPU twin for
//! random rays through an N³ grid (default 256³), plus the GPU/CPU parity of the walks.
//!
//! Rays: 80 % start on a sphere of radius N around the box (outside it) aimed at a uniform point
//! inside, 20 % start at a uniform point inside with a uniform direction. The timed runs record no
//! cells (`k = 0`: every walk is counted and checksummed only), so they measure the walk itself.
//! GPU figure: device time from timestamp queries (best of `--repeats`); CPU: wall time of the
//! rayon twin (best of `--repeats`). Parity: count and checksum of every walk exactly, and the
//! first 64 cells with their t of the first 8192 rays (`check::dda_walk::compare_into`).

use crate::check::dda_walk::{compare_into, run_cpu, run_gpu, sphere_rays, T_ABS, T_REL};
use crate::check::Compare;
use crate::gpu::Gpu;
use anyhow::{ensure, Result};
use std::time::Instant;

/// Arguments of `bench dda`.
#[derive(clap::Args, Debug)]
pub struct DdaBenchArgs {
    /// Print one JSON object with the figures and `pass` as the last stdout line.
    #[arg(long)]
    pub json: bool,
    /// Number of rays.
    #[arg(long, default_value_t = 1 << 20)]
    pub rays: usize,
    /// Grid resolution N (vertices per axis).
    #[arg(long, default_value_t = 256)]
    pub res: u32,
    /// Seed of the random rays.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Timed runs per backend (the best is reported).
    #[arg(long, default_value_t = 3)]
    pub repeats: usize,
}

/// Cells recorded per ray in the parity run.
const PARITY_K: u32 = 64;
/// Rays in the parity run that records cells.
const PARITY_RAYS: usize = 8192;

/// Run the benchmark and print it; returns the parity verdict.
pub fn run(gpu: &Gpu, args: &DdaBenchArgs) -> Result<bool> {
    ensure!(
        (2..=1024).contains(&args.res),
        "--res must be in 2..=1024, got {}",
        args.res
    );
    ensure!(
        args.rays >= 1 && args.rays <= 1 << 24,
        "--rays must be in 1..=16777216"
    );
    ensure!(args.repeats >= 1, "--repeats must be at least 1");
    let n = args.res;
    let rays = sphere_rays(args.rays, n, args.seed, 0.2);

    // Warm-up: pipeline compilation happens at the first dispatch on lavapipe.
    let warm = &rays[..rays.len().min(4096)];
    run_gpu(gpu, warm, n, 0, 0.0)?;
    run_cpu(warm, n, 0, 0.0);

    let mut gpu_ns = f64::INFINITY;
    let mut gpu_out = None;
    for _ in 0..args.repeats {
        let (out, ns) = run_gpu(gpu, &rays, n, 0, 0.0)?;
        gpu_ns = gpu_ns.min(ns);
        gpu_out = Some(out);
    }
    let gpu_out = gpu_out.expect("at least one repeat");
    let mut cpu_s = f64::INFINITY;
    let mut cpu_out = None;
    for _ in 0..args.repeats {
        let t = Instant::now();
        let out = run_cpu(&rays, n, 0, 0.0);
        cpu_s = cpu_s.min(t.elapsed().as_secs_f64());
        cpu_out = Some(out);
    }
    let cpu_out = cpu_out.expect("at least one repeat");

    let cells = cpu_out.total_cells();
    let mut cmp = Compare::new(T_ABS, T_REL);
    compare_into(&mut cmp, &gpu_out, &cpu_out, "all rays");
    let sub = &rays[..rays.len().min(PARITY_RAYS)];
    let (g, _) = run_gpu(gpu, sub, n, PARITY_K, 0.0)?;
    let c = run_cpu(sub, n, PARITY_K, 0.0);
    compare_into(&mut cmp, &g, &c, "recorded");
    let pass = cmp.failures == 0 && cmp.compared > 0;

    let gpu_rate = cells as f64 / (gpu_ns * 1e-9);
    let cpu_rate = cells as f64 / cpu_s;
    let threads = rayon::current_num_threads();
    let info = gpu.info();
    println!(
        "bench dda: {} rays through a {n}³ grid, {cells} cells visited ({:.1} per ray)",
        rays.len(),
        cells as f64 / rays.len() as f64
    );
    println!(
        "{:<40} {:>12} {:>14} {:>12}",
        "backend", "time", "cells/s", "rays/s"
    );
    println!(
        "{:<40} {:>9.2} ms {:>14.3e} {:>12.3e}",
        format!("vulkan: {}", info.name),
        gpu_ns * 1e-6,
        gpu_rate,
        rays.len() as f64 / (gpu_ns * 1e-9)
    );
    println!(
        "{:<40} {:>9.2} ms {:>14.3e} {:>12.3e}",
        format!("cpu twin: rayon, {threads} threads"),
        cpu_s * 1e3,
        cpu_rate,
        rays.len() as f64 / cpu_s
    );
    let failure = cmp.first_failure.clone().unwrap_or_default();
    println!(
        "parity: {} ({} comparisons, {} failures; counts and checksums of every walk exact, \
         first {PARITY_K} cells of {} rays, t max abs {:.2e}) {failure}",
        if pass { "pass" } else { "FAIL" },
        cmp.compared,
        cmp.failures,
        sub.len(),
        cmp.max_abs
    );
    if args.json {
        let j = serde_json::json!({
            "bench": "dda",
            "res": n,
            "rays": rays.len(),
            "cells": cells,
            "cells_per_ray": cells as f64 / rays.len() as f64,
            "device": info.name,
            "gpu_ms": gpu_ns * 1e-6,
            "gpu_cells_per_s": gpu_rate,
            "cpu_ms": cpu_s * 1e3,
            "cpu_threads": threads,
            "cpu_cells_per_s": cpu_rate,
            "parity_comparisons": cmp.compared,
            "parity_failures": cmp.failures,
            "parity_t_max_abs": cmp.max_abs,
            "pass": pass,
        });
        println!("{j}");
    }
    Ok(pass)
}
