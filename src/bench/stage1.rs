//! Stage-1 pieces shared by `bench plenoxels` and `bench surface`: the built-in thin scene they
//! train on, the short fast-preset run that prepares a grid, and the timed training steps.

use crate::abi::buffers::PlenoxelPerRay;
use crate::data::{Dataset, LoadOptions, TrainViews};
use crate::gpu::StepTimes;
use crate::grid::Grid;
use crate::plenoxel::PlenoxelsBackend;
use crate::scene::{generate, GenerateOptions, SceneKind};
use crate::train::progress::READ_EVERY;
use crate::train::PlenoxelsConfig;
use anyhow::Result;
use std::path::Path;
use std::time::Instant;

/// Generates the thin scene (128², 40 views; small images, so the benches stay quick) into
/// `dir` and loads it.
pub fn thin_scene(dir: &Path) -> Result<Dataset> {
    let mut opts = GenerateOptions::new(SceneKind::Thin);
    (opts.res, opts.views, opts.spp_side, opts.gt_spacing) = (128, 40, 2, 0.05);
    opts.overwrite = true; // the bench's own temporary folder
    generate(dir, &opts)?;
    Dataset::load(dir, &LoadOptions::default())
}

/// The fast preset for `iters` steps from a (`res`/2)³ grid upsampled to `res`³ after a third
/// of them, without checkpoints; and its initial grid.
pub fn warm_config(res: u32, iters: u32) -> (PlenoxelsConfig, Grid) {
    let mut cfg = PlenoxelsConfig::fast();
    cfg.res = res / 2;
    cfg.upsample = vec![(iters / 3, res)];
    cfg.iters = iters;
    cfg.checkpoint_every = u32::MAX;
    let grid = Grid::sphere(cfg.res, [0.0; 3], [1.0; 3], 1.0, cfg.init_sigma);
    (cfg, grid)
}

/// One backend's figures.
#[derive(Debug, Default, serde::Serialize)]
pub struct Figures {
    /// Rays over the time spent in the backend's step calls (drawing the batch included, the
    /// loop's bookkeeping excluded).
    pub rays_per_s: f64,
    pub mean_mse: f64,
    /// The march's counters per ray.
    pub per_ray: PlenoxelPerRay,
    #[serde(flatten)]
    pub times: StepFigures,
}

/// Where a step's time goes, per step (ms): `wall_ms_per_step` is the whole loop iteration
/// (sampling, step, bookkeeping) and equals the sum of `host_ms`, whose `other` is the part in
/// no named phase; `device_ms_total_per_step` is the sum of the kernels' timestamps on Vulkan
/// (inside `host_ms.wait`) and the twin's compute on the CPU (`host_ms.compute`).
#[derive(Debug, Default, serde::Serialize)]
pub struct StepFigures {
    pub wall_ms_per_step: f64,
    pub device_ms_total_per_step: f64,
    pub host_ms: StepTimes,
}

impl StepFigures {
    /// Accumulates one step: its wall ms, the phases measured around and inside it, and its
    /// device ns (0 on the CPU backend, whose kernels are its `compute`).
    pub fn add(&mut self, wall_ms: f64, phases: &StepTimes, device_ns: f64) {
        self.wall_ms_per_step += wall_ms;
        self.host_ms.add(phases);
        self.device_ms_total_per_step += if device_ns > 0.0 {
            device_ns / 1e6
        } else {
            phases.compute
        };
    }

    /// Sums of `steps` steps to means per step; the wall time in no phase becomes `other`.
    pub fn per_step(mut self, steps: u32) -> StepFigures {
        self.host_ms.other += (self.wall_ms_per_step - self.host_ms.total()).max(0.0);
        let k = 1.0 / steps as f64;
        StepFigures {
            wall_ms_per_step: self.wall_ms_per_step * k,
            device_ms_total_per_step: self.device_ms_total_per_step * k,
            host_ms: self.host_ms.scaled(k),
        }
    }

    /// A table row: wall, device, then every host phase, in ms.
    pub fn row(&self) -> String {
        let mut s = format!(
            "{:>8.3} {:>8.3}",
            self.wall_ms_per_step, self.device_ms_total_per_step
        );
        for (_, ms) in self.host_ms.phases() {
            s += &format!(" {ms:>11.3}");
        }
        s
    }

    /// The header of [`row`](Self::row), after a `width`-wide label column.
    pub fn header(label: &str, width: usize) -> String {
        let mut s = format!("{label:<width$} {:>8} {:>8}", "wall", "device");
        for (name, _) in StepTimes::default().phases() {
            s += &format!(" {name:>11}");
        }
        s
    }
}

/// `steps + 1` stage-1 training steps (no TV, the learning rates of the schedule's end) of
/// `batch` rays drawn with seeds 7, 8, … (on the device on Vulkan, by the twin on the CPU), run as
/// training runs them (submitted without waiting, figures read every `READ_EVERY` steps); the
/// first is untimed (first-dispatch compilation on lavapipe). The wall time is the whole loop's.
pub fn time_steps(
    backend: &mut dyn PlenoxelsBackend,
    data: &Dataset,
    cfg: &PlenoxelsConfig,
    steps: u32,
    batch: u32,
) -> Result<Figures> {
    let mut f = Figures::default();
    let mut times = StepFigures::default();
    let views = TrainViews::new(&data.train, &data.scene)?;
    let p = cfg.step_params(cfg.iters, None);
    backend.step_sampled(&views, 7, batch as usize, &p)?;
    backend.take_stats()?;
    let wall = Instant::now();
    for step in 1..=steps {
        backend.step_sampled(&views, 7 + step as u64, batch as usize, &p)?;
        if step % READ_EVERY == 0 || step == steps {
            for s in backend.take_stats()? {
                f.mean_mse += s.mse / steps as f64;
                f.per_ray.add(&s.counts);
                times.add(0.0, &s.timing.host, s.timing.device_ns);
            }
        }
    }
    let secs = wall.elapsed().as_secs_f64();
    times.wall_ms_per_step = secs * 1e3;
    f.rays_per_s = (batch * steps) as f64 / secs;
    f.per_ray = f.per_ray.scaled(1.0 / (batch * steps) as f64);
    f.times = times.per_step(steps);
    Ok(f)
}
