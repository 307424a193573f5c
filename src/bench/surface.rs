//! `alphasurf bench surface`: stage-2 (αSurf) training throughput on both backends from the same
//! grid. The built-in thin scene is generated (small images, as `bench plenoxels`), a short
//! fast-preset stage-1 run on the CPU backend brings a density grid to `--res`³, the stage-2 grid
//! is initialised from it (method.md §3.1, `SurfaceGrid::from_density`) and trained for
//! `--warm-steps` CPU steps, then each backend trains the same `--steps` batches from that state
//! (the thin category's fast-preset weights and regulariser chunks at step 0: LH, Lc, Lδ over every
//! vertex, TVα, Lα and Ln1/Ln2 on random chunks). Reported per backend: training rays/s (wall time,
//! after one untimed step), mean MSE, and per ray: cells read (live cells), cubic solves, solves
//! skipped by min/max or segment culling, hits composited, hits cut by truncation, hits whose δ
//! gradient the f′ guard dropped, gradient atomic adds; the Vulkan/CPU ratio; the Vulkan device
//! time per kernel (timestamps); per step, the wall time of the loop iteration, the device time
//! and the host time by phase (`StepFigures`). The Vulkan backend is also timed without the
//! regularisers (the data term, its scatter and RMSProp over the vertices the rays touched):
//! `bench plenoxels` times stage-1 steps without TV, and Lδ alone touches every vertex each step.
//! For the target it times stage-1 training on the Vulkan device at the same resolution,
//! from the stage-1 grid, the way `bench plenoxels` does, in `--rounds` rounds of stage 1 then
//! stage 2 back to back (the machine's speed drifts), and reports every round's ratio and the
//! round with the median one.

use super::stage1::{thin_scene, time_steps, warm_config, StepFigures};
use crate::abi::buffers::{TrainCounts, TrainPerRay};
use crate::data::{Dataset, TrainViews};
use crate::gpu::Gpu;
use crate::grid::surface::SurfaceGrid;
use crate::grid::Grid;
use crate::math::surface::Truncation;
use crate::plenoxel::{CpuPlenoxels, VulkanPlenoxels};
use crate::stage::StageBackend;
use crate::surface::{CpuSurface, SurfaceBackend, SurfaceRegs, SurfaceStepParams, VulkanSurface};
use crate::train::progress::READ_EVERY;
use crate::train::surface_config::SurfaceConfig;
use crate::train::{plenoxels_steps, surface_steps, Category, PlenoxelsConfig, Preset};
use anyhow::{ensure, Result};
use serde_json::json;
use std::collections::BTreeMap;
use std::time::Instant;

/// Arguments of `bench surface`.
#[derive(clap::Args, Debug)]
pub struct SurfaceBenchArgs {
    /// Print one JSON object with the figures as the last stdout line.
    #[arg(long)]
    pub json: bool,
    /// Grid resolution.
    #[arg(long, default_value_t = 128)]
    pub res: u32,
    /// Fast-preset stage-1 steps (CPU backend) that prepare the density grid.
    #[arg(long, default_value_t = 300)]
    pub stage1_steps: u32,
    /// Stage-2 steps (CPU backend) after the initialisation, before timing.
    #[arg(long, default_value_t = 20)]
    pub warm_steps: u32,
    /// Timed steps per backend.
    #[arg(long, default_value_t = 20)]
    pub steps: u32,
    /// Rounds of stage-1 then stage-2 Vulkan timing (odd: the round with the median ratio is
    /// reported).
    #[arg(long, default_value_t = 3)]
    pub rounds: u32,
    /// Rays per batch.
    #[arg(long, default_value_t = 4096)]
    pub batch: u32,
    /// Truncation parameter a (the schedule runs 5 → 2).
    #[arg(long, default_value_t = 5.0)]
    pub a: f32,
}

/// One backend's figures.
#[derive(Debug, Default, serde::Serialize)]
struct Figures {
    rays_per_s: f64,
    mean_mse: f64,
    /// The training pass's counters per ray.
    per_ray: TrainPerRay,
    /// Device ms per step and kernel (Vulkan only).
    device_ms_per_step: BTreeMap<&'static str, f64>,
    #[serde(flatten)]
    times: StepFigures,
}

/// The stage-2 step parameters of the thin category's fast preset at step 0 (as the training
/// loop builds them, with chunk positions drawn from the step index), truncation `a`.
fn step_params(
    cfg: &SurfaceConfig,
    res: [u32; 3],
    rows: u32,
    a: f32,
    step: u32,
) -> SurfaceStepParams {
    let draw = (step as u64 + 1).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    let truncation = Truncation {
        a,
        count: cfg.truncation_count,
    };
    surface_steps::step_params(cfg, res, rows, 0, truncation, [draw, draw >> 17, draw >> 7])
}

/// `steps + 1` stage-2 steps (the first untimed) on the batches of `n` rays drawn from `views`
/// with seeds 11, 12, …, run as training runs them (submitted without waiting, figures read every
/// `READ_EVERY` steps); `regs`: with the regularisers, else the data term alone. The wall time is
/// the whole loop's; `after_warm_up` is called between the untimed step and the timed ones.
#[allow(clippy::too_many_arguments)]
fn time_surface(
    backend: &mut dyn SurfaceBackend,
    after_warm_up: &mut dyn FnMut(),
    views: &TrainViews,
    n: usize,
    grid: &SurfaceGrid,
    cfg: &SurfaceConfig,
    args: &SurfaceBenchArgs,
    regs: bool,
) -> Result<Figures> {
    let mut f = Figures::default();
    let mut times = StepFigures::default();
    let mut counts = TrainPerRay::default();
    let params = |i: u32| {
        let mut p = step_params(cfg, grid.res, grid.delta.len() as u32, args.a, i);
        if !regs {
            p.regs = SurfaceRegs::default();
        }
        p
    };
    // Warm-up: first-dispatch compilation on lavapipe.
    backend.step_sampled(views, 11, n, &params(0))?;
    backend.take_stats()?;
    after_warm_up();
    let wall = Instant::now();
    for i in 1..=args.steps {
        backend.step_sampled(views, 11 + i as u64, n, &params(i))?;
        if i % READ_EVERY == 0 || i == args.steps {
            for s in backend.take_stats()? {
                f.mean_mse += s.mse / args.steps as f64;
                counts.add(&s.counts);
                times.add(0.0, &s.timing.host, s.timing.device_ns);
            }
        }
    }
    let secs = wall.elapsed().as_secs_f64();
    times.wall_ms_per_step = secs * 1e3;
    let rays = (args.batch * args.steps) as f64;
    f.rays_per_s = rays / secs;
    f.times = times.per_step(args.steps);
    f.per_ray = counts.scaled(1.0 / rays);
    Ok(f)
}

/// Device ns per kernel that `gpu` ran since `before` (a `Profile::totals` snapshot).
fn kernel_ns_since(gpu: &Gpu, before: &[(&'static str, u64, f64)]) -> BTreeMap<&'static str, f64> {
    let mut ns: BTreeMap<&'static str, f64> = gpu
        .profile()
        .totals()
        .into_iter()
        .map(|(k, _, t)| (k, t))
        .collect();
    for (k, _, t) in before {
        if let Some(v) = ns.get_mut(k) {
            *v -= t;
        }
    }
    ns.retain(|_, v| *v > 0.0);
    ns
}

/// Run the benchmark and print it.
pub fn run(gpu: &Gpu, args: &SurfaceBenchArgs) -> Result<()> {
    ensure!((16..=512).contains(&args.res), "--res must be in 16..=512");
    ensure!(
        args.steps >= 1 && args.batch >= 1 && args.stage1_steps >= 3,
        "--steps and --batch must be at least 1, --stage1-steps at least 3"
    );
    ensure!(
        args.rounds % 2 == 1,
        "--rounds must be odd (the round with the median ratio is reported), got {}",
        args.rounds
    );
    ensure!(
        args.a > 0.0 && args.a <= 8.0,
        "--a must be in (0, 8], got {}",
        args.a
    );
    let dir = std::env::temp_dir().join(format!("alphasurf-bench-surface-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let result = run_in(gpu, args, &dir);
    let _ = std::fs::remove_dir_all(&dir);
    result
}

/// What the timings start from: the stage-1 config and density grid, the stage-2 grid and its
/// optimiser state after the warm-up steps.
struct Start {
    cfg: PlenoxelsConfig,
    density: Grid,
    grid: SurfaceGrid,
    state: [Vec<f32>; 3],
}

/// Stage 1, briefly, on the CPU backend (the faster one on a CPU-only machine), then the stage-2
/// grid initialised from it and `--warm-steps` CPU steps on batches from `views`.
fn warm_start(
    data: &Dataset,
    views: &TrainViews,
    scfg: &SurfaceConfig,
    args: &SurfaceBenchArgs,
    dir: &std::path::Path,
) -> Result<Start> {
    let (cfg, grid0) = warm_config(args.res, args.stage1_steps);
    let mut s1 = CpuPlenoxels::new(grid0);
    eprintln!(
        "bench surface: {} stage-1 steps (CPU) to reach a {}³ density grid",
        cfg.iters, args.res
    );
    plenoxels_steps::train(&mut s1, data, &cfg, &dir.join("stage1"), 0, false)?;
    let density = s1.grid()?;
    let init_grid = SurfaceGrid::from_density(&density, &scfg.init)?;
    let (res, rows) = (init_grid.res, init_grid.delta.len() as u32);
    let mut cpu = CpuSurface::new(init_grid)?;
    eprintln!(
        "bench surface: {} stage-2 warm-up steps (CPU)",
        args.warm_steps
    );
    for i in 0..args.warm_steps {
        let p = step_params(scfg, res, rows, args.a, i);
        cpu.step_sampled(views, 3 + i as u64, args.batch as usize, &p)?;
    }
    Ok(Start {
        cfg,
        density,
        grid: cpu.grid()?,
        state: cpu.optimizer_state()?,
    })
}

/// The timings' shared inputs.
struct Bench<'a> {
    gpu: &'a Gpu,
    args: &'a SurfaceBenchArgs,
    data: &'a Dataset,
    /// Batches drawn as training draws them (the preset's focus on the object's pixels).
    views: &'a TrainViews<'a>,
    scfg: &'a SurfaceConfig,
    start: &'a Start,
}

impl Bench<'_> {
    /// Stage-1 training rays/s on the Vulkan device from the density grid (a fresh backend).
    fn stage1(&self) -> Result<f64> {
        let s = self.start;
        let mut vk = VulkanPlenoxels::new(self.gpu, s.density.clone())?;
        let (steps, batch) = (self.args.steps, self.args.batch);
        Ok(time_steps(&mut vk, self.data, &s.cfg, steps, batch)?.rays_per_s)
    }

    /// The Vulkan backend from the warm state, with the regularisers or the data term alone.
    fn vulkan(&self, regs: bool) -> Result<Figures> {
        let (gpu, s) = (self.gpu, self.start);
        let mut vk = VulkanSurface::new(gpu, s.grid.clone())?;
        vk.load(s.grid.clone(), Some(s.state.clone()))?;
        // The warm-up step is timed by the profile too: take the snapshot after it.
        let mut before = Vec::new();
        let mut f = self.time(&mut vk, &mut || before = gpu.profile().totals(), regs)?;
        let kernel_ns = kernel_ns_since(gpu, &before);
        f.device_ms_per_step = kernel_ns
            .into_iter()
            .map(|(k, ns)| (k, ns / 1e6 / self.args.steps as f64))
            .collect();
        Ok(f)
    }

    /// The CPU backend from the warm state, with the regularisers.
    fn cpu(&self) -> Result<Figures> {
        let s = self.start;
        let mut cpu = CpuSurface::new(s.grid.clone())?;
        cpu.load(s.grid.clone(), Some(s.state.clone()))?;
        self.time(&mut cpu, &mut || (), true)
    }

    fn time(
        &self,
        backend: &mut dyn SurfaceBackend,
        after_warm_up: &mut dyn FnMut(),
        regs: bool,
    ) -> Result<Figures> {
        let n = self.args.batch as usize;
        let grid = &self.start.grid;
        time_surface(
            backend,
            after_warm_up,
            self.views,
            n,
            grid,
            self.scfg,
            self.args,
            regs,
        )
    }
}

/// The figures reported: the Vulkan backend (the median round's), the CPU backend and the Vulkan
/// backend on the data term alone; per round stage-1 rays/s, stage-2 rays/s and their ratio; the
/// median round's stage-1 rays/s.
struct Report {
    vulkan: Figures,
    cpu: Figures,
    data_term: Figures,
    paired: Vec<[f64; 3]>,
    stage1_vk: f64,
}

impl Report {
    /// Rounds of stage 1 then stage 2 back to back: the machine's speed drifts from run to run and
    /// within one (docs/results.md), so each ratio pairs two timings taken seconds apart, and the
    /// round with the median ratio is reported.
    fn measure(b: &Bench) -> Result<Report> {
        let rounds = b.args.rounds;
        let mut figures = Vec::new();
        for r in 1..=rounds {
            eprintln!(
                "bench surface: round {r}/{rounds}: stage-1 then stage-2 training on the Vulkan \
                 device"
            );
            let stage1 = b.stage1()?;
            figures.push((stage1, b.vulkan(true)?));
        }
        let paired: Vec<[f64; 3]> = figures
            .iter()
            .map(|(s1, f)| [*s1, f.rays_per_s, f.rays_per_s / s1])
            .collect();
        let mut order: Vec<usize> = (0..paired.len()).collect();
        order.sort_by(|&i, &j| paired[i][2].total_cmp(&paired[j][2]));
        let median = order[order.len() / 2];
        eprintln!("bench surface: timing the Vulkan backend (data term only)");
        let data_term = b.vulkan(false)?;
        let (stage1_vk, vulkan) = figures.swap_remove(median);
        eprintln!("bench surface: timing the CPU backend");
        let cpu = b.cpu()?;
        Ok(Report {
            vulkan,
            cpu,
            data_term,
            paired,
            stage1_vk,
        })
    }

    fn rows(&self) -> [(&'static str, &Figures); 3] {
        [
            ("vulkan", &self.vulkan),
            ("cpu", &self.cpu),
            ("vk-data", &self.data_term),
        ]
    }

    /// Prints the tables and ratios.
    fn print(&self, args: &SurfaceBenchArgs, grid: &SurfaceGrid) {
        println!(
            "stage-2 training at {}³ ({} allocated vertices, {} levels), {} steps of {} rays, a = \
             {}, thin scene",
            args.res,
            grid.delta.len(),
            grid.levels.len(),
            args.steps,
            args.batch,
            args.a
        );
        print!("{:<8} {:>10} {:>9}", "backend", "rays/s", "mse");
        for k in TrainCounts::NAMES {
            print!(" {k:>8}");
        }
        println!("   (per ray)");
        for (name, f) in self.rows() {
            print!("{name:<8} {:>10.0} {:>9.5}", f.rays_per_s, f.mean_mse);
            for (k, v) in f.per_ray.named() {
                print!(" {v:>w$.2}", w = k.len().max(8));
            }
            println!();
        }
        println!(
            "(vk-data: the Vulkan backend without the regularisers, like `bench plenoxels`' steps)"
        );
        println!(
            "vulkan / cpu: {:.2}×",
            self.vulkan.rays_per_s / self.cpu.rays_per_s
        );
        println!(
            "ms per step: wall, device (kernels' timestamps; the CPU: its compute), host phases:"
        );
        println!("{}", StepFigures::header("backend", 8));
        for (name, f) in self.rows() {
            println!("{name:<8} {}", f.times.row());
        }
        for (what, f) in [("", &self.vulkan), (", data term only", &self.data_term)] {
            println!("device ms per step (Vulkan{what}):");
            for (k, ms) in &f.device_ms_per_step {
                println!("  {k:<20} {ms:>9.3}");
            }
        }
        let column = |k: usize, fmt: fn(f64) -> String| {
            self.paired
                .iter()
                .map(|r| fmt(r[k]))
                .collect::<Vec<_>>()
                .join(" / ")
        };
        println!(
            "stage-1 training on the Vulkan device at {}³ (no TV, as `bench plenoxels`), {} rounds \
             of stage 1 then stage 2: stage 1 {} rays/s, stage 2 {}, ratios {}",
            args.res,
            self.paired.len(),
            column(0, |v| format!("{v:.0}")),
            column(1, |v| format!("{v:.0}")),
            column(2, |v| format!("{v:.2}×")),
        );
        println!(
            "stage 2 / stage 1 (the median round; the table's Vulkan row is that round's): \
             {:.2}× with the regularisers, {:.2}× data term only (target ≥ 3×)",
            self.vulkan.rays_per_s / self.stage1_vk,
            self.data_term.rays_per_s / self.stage1_vk
        );
    }

    /// The figures as one JSON object.
    fn json(&self, gpu: &Gpu, args: &SurfaceBenchArgs, grid: &SurfaceGrid) -> serde_json::Value {
        json!({
            "bench": "surface",
            "device": gpu.info().name,
            "res": args.res,
            "allocated_vertices": grid.delta.len(),
            "levels": grid.levels.len(),
            "a": args.a,
            "batch": args.batch,
            "steps": args.steps,
            "vulkan": self.vulkan,
            "vulkan_data_term_only": self.data_term,
            "cpu": self.cpu,
            "ratio_vulkan_over_cpu": self.vulkan.rays_per_s / self.cpu.rays_per_s,
            "stage1_vulkan_rays_per_s": self.stage1_vk,
            "rounds": self
                .paired
                .iter()
                .map(|r| json!({
                    "stage1_rays_per_s": r[0],
                    "surface_rays_per_s": r[1],
                    "ratio": r[2],
                }))
                .collect::<Vec<_>>(),
            "ratio_surface_over_stage1_vulkan": self.vulkan.rays_per_s / self.stage1_vk,
            "ratio_surface_data_term_over_stage1_vulkan": self.data_term.rays_per_s / self.stage1_vk,
        })
    }
}

fn run_in(gpu: &Gpu, args: &SurfaceBenchArgs, dir: &std::path::Path) -> Result<()> {
    eprintln!("bench surface: generating the thin scene (128², 40 views)");
    let data = thin_scene(&dir.join("scene"))?;
    let scfg = SurfaceConfig::preset(Preset::Fast, Category::Thin)?;
    let views = TrainViews::new(&data.train, &data.scene)?.focused(scfg.ray_focus)?;
    let start = warm_start(&data, &views, &scfg, args, dir)?;
    let bench = Bench {
        gpu,
        args,
        data: &data,
        views: &views,
        scfg: &scfg,
        start: &start,
    };
    let report = Report::measure(&bench)?;
    report.print(args, &start.grid);
    if args.json {
        println!("{}", report.json(gpu, args, &start.grid));
    }
    Ok(())
}
