//! Stage-1 pieces shared by `bench plenoxels` and `bench surface`: the built-in thin scene they
//! train on, the short fast-preset run that prepares a grid, and the timed training steps.

use crate::abi::buffers::PlenoxelPerRay;
use crate::data::{Dataset, LoadOptions, RaySampler};
use crate::grid::Grid;
use crate::plenoxel::{Plenoxels, StepParams};
use crate::scene::{generate, GenerateOptions, SceneKind};
use crate::train::Stage1Config;
use anyhow::Result;
use std::path::Path;
use std::time::Instant;

/// Generates the thin scene (128², 40 views; small images, so the benches stay quick) into
/// `dir` and loads it.
pub fn thin_scene(dir: &Path) -> Result<Dataset> {
    let mut opts = GenerateOptions::new(SceneKind::Thin);
    (opts.res, opts.views, opts.spp_side, opts.gt_spacing) = (128, 40, 2, 0.05);
    generate(dir, &opts)?;
    Dataset::load(dir, &LoadOptions::default())
}

/// The fast preset for `iters` steps from a (`res`/2)³ grid upsampled to `res`³ after a third
/// of them, without checkpoints; and its initial grid.
pub fn warm_config(res: u32, iters: u32) -> (Stage1Config, Grid) {
    let mut cfg = Stage1Config::fast();
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
    pub rays_per_s: f64,
    pub mean_mse: f64,
    /// The march's counters per ray.
    pub per_ray: PlenoxelPerRay,
}

/// `steps + 1` stage-1 training steps (no TV, the learning rates of the schedule's end) of
/// `batch` rays from a fixed sampler; the first is untimed (first-dispatch compilation on
/// lavapipe).
pub fn time_steps(
    backend: &mut dyn Plenoxels,
    data: &Dataset,
    cfg: &Stage1Config,
    steps: u32,
    batch: u32,
) -> Result<Figures> {
    let mut f = Figures::default();
    let mut secs = 0.0;
    let mut sampler = RaySampler::new(&data.train, 7);
    for step in 0..=steps {
        let b = sampler.next_batch(&data.train, &data.scene, batch as usize);
        let (rays, targets) = (b.flat_rays(), b.flat_targets());
        let t = Instant::now();
        let s = backend.step(
            &rays,
            &targets,
            &StepParams {
                lr_sigma: cfg.lr_sigma.at(cfg.iters),
                lr_sh: cfg.lr_sh.at(cfg.iters),
                beta: cfg.beta,
                eps: cfg.eps,
                stop_thresh: cfg.stop_thresh,
                tv: None,
            },
        )?;
        if step == 0 {
            continue;
        }
        secs += t.elapsed().as_secs_f64();
        f.mean_mse += s.mse / steps as f64;
        f.per_ray.add(&s.counts);
    }
    f.rays_per_s = (batch * steps) as f64 / secs;
    f.per_ray = f.per_ray.scaled(1.0 / (batch * steps) as f64);
    Ok(f)
}
