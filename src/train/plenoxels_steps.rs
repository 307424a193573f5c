//! Stage 1 (Plenoxels) in the training loop ([`super::steps`]): TV on a random slot chunk per
//! step, upsampling with weight pruning on schedule, the background a run starts with, the test
//! renders.

use super::config::PlenoxelsConfig;
use super::progress::Progress;
use super::render::{render_split, RenderedSplit};
use super::steps::{self, LoopReport, StageSteps};
use crate::abi::buffers::PlenoxelPerRay;
use crate::checkpoint::{Backdrop, BackgroundRecord};
use crate::data::{Dataset, Split};
use crate::grid::{dilate, upsample, Grid};
use crate::plenoxel::{PlenoxelsBackend, PlenoxelsStage, PlenoxelsStepParams, TvParams};
use crate::run::memory;
use anyhow::{bail, Context, Result};
use rand::Rng;
use rand_pcg::Pcg64;
use std::path::Path;
use std::time::Instant;

/// A finished stage-1 run: the loop's figures, the upsamplings' wall time and the grid's size.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct PlenoxelsReport {
    /// Per training ray: the march's counters (samples shaded, evaluated at σ ≤ ε, skipped by
    /// the occupancy volume; gradient atomic adds).
    pub run: LoopReport<PlenoxelPerRay>,
    pub upsample_seconds: f64,
    pub allocated_vertices: usize,
    pub bytes_per_vertex: f64,
}

/// Rays (6 floats each) of every `stride`-th pixel per axis of every view of a split.
fn strided_rays(data: &Dataset, split: &Split, stride: u32) -> Vec<f32> {
    let mut rays = Vec::new();
    for f in &split.frames {
        for y in (0..split.height()).step_by(stride as usize) {
            for x in (0..split.width()).step_by(stride as usize) {
                let (o, d) = f.camera.pixel_ray(x, y);
                rays.extend_from_slice(&data.scene.ray(o, d));
            }
        }
    }
    rays
}

/// Prune by training-ray weight, dilate twice, resample to `new_res` (optimiser state resets).
fn upsample_step(
    backend: &mut dyn PlenoxelsBackend,
    data: &Dataset,
    cfg: &PlenoxelsConfig,
    new_res: u32,
) -> Result<()> {
    let grid = backend.grid()?;
    let rays = strided_rays(data, &data.train, cfg.prune_pixel_stride);
    let mut weights = vec![0f32; grid.allocated()];
    for chunk in rays.chunks(6 * 262_144) {
        let w = backend.max_weights(chunk, cfg.prune_stop_thresh)?;
        for (a, b) in weights.iter_mut().zip(w) {
            *a = a.max(b);
        }
    }
    let keep: Vec<bool> = grid
        .links
        .iter()
        .map(|&l| l >= 0 && weights[l as usize] >= cfg.prune_weight)
        .collect();
    let keep = dilate(grid.res, &keep, 2);
    // Refused before the rows are allocated (a barely trained grid keeps nearly every vertex).
    let next = upsample(&grid, new_res, &keep, |vertices| {
        memory::ensure_fits(
            &format!("upsampling to {new_res}³ ({vertices} vertices kept)"),
            Grid::training_bytes([new_res; 3], vertices),
        )
        .context(
            "too few vertices were pruned by training-ray weight before the upsampling \
             (more --iters, or a smaller --res)",
        )
    })?;
    if next.allocated() == 0 {
        bail!(
            "upsampling to {new_res}³ kept no vertex (no training-ray weight reached {}); \
             the scene may be empty, its cameras may not see the scene box (see the warnings \
             of `alphasurf inspect` on the dataset) or training diverged",
            cfg.prune_weight
        );
    }
    backend.load(next, None)
}

/// Stage 1's part of a run: its configuration, and the seconds its upsamplings took.
pub struct PlenoxelsSteps<'a> {
    pub cfg: &'a PlenoxelsConfig,
    pub upsample_seconds: f64,
}

/// Stage 1's part of the loop.
impl<'b> StageSteps<PlenoxelsStage, dyn PlenoxelsBackend + 'b> for PlenoxelsSteps<'_> {
    type Config = PlenoxelsConfig;

    fn config(&self) -> &PlenoxelsConfig {
        self.cfg
    }

    /// From step 0 the background starts as `data.background` says
    /// (`BackgroundRecord::start_on`, with its spheres); a resumed run keeps the one its
    /// checkpoint holds.
    fn start(
        &mut self,
        backend: &mut (dyn PlenoxelsBackend + 'b),
        data: &Dataset,
        start_step: u32,
    ) -> Result<()> {
        if start_step == 0 {
            let record = BackgroundRecord::start_on(data);
            let spheres = record.start_spheres(data)?;
            Backdrop { record, spheres }.install(backend)?;
        }
        Ok(())
    }

    fn before_step(
        &mut self,
        backend: &mut (dyn PlenoxelsBackend + 'b),
        data: &Dataset,
        step: u32,
        progress: &mut Progress,
    ) -> Result<bool> {
        let Some((_, r)) = self.cfg.upsample.iter().find(|(s, _)| *s == step) else {
            return Ok(false);
        };
        let t = Instant::now();
        progress.message(&format!(
            "upsampling to {r}³ (pruning by training-ray weight)"
        ));
        upsample_step(backend, data, self.cfg, *r)?;
        self.upsample_seconds += t.elapsed().as_secs_f64();
        Ok(true)
    }

    fn params(&mut self, step: u32, rng: &mut Pcg64) -> PlenoxelsStepParams {
        let cfg = self.cfg;
        let tv_on = !(cfg.tv_until_upsample && cfg.upsample.iter().any(|(s, _)| *s <= step));
        let slots = cfg.res_at(step).pow(3);
        let count = ((slots as f32 * cfg.tv_fraction) as u32).max(1);
        let tv = (tv_on && (cfg.tv_sigma > 0.0 || cfg.tv_sh > 0.0)).then(|| TvParams {
            start: rng.random_range(0..=slots - count),
            count,
            lambda_sigma: cfg.tv_sigma,
            lambda_sh: cfg.tv_sh,
        });
        cfg.step_params(step, tv)
    }

    fn work_before(&self, step: u32) -> bool {
        self.cfg.upsample.iter().any(|(s, _)| *s == step)
    }

    fn render_test(
        &mut self,
        backend: &mut (dyn PlenoxelsBackend + 'b),
        data: &Dataset,
        out: &Path,
    ) -> Result<RenderedSplit> {
        render_split(backend, data, &data.test, self.cfg.stop_thresh, out, 1)
    }
}

/// Train stage 1 from `start_step` (0, or the step after a resumed checkpoint) to `cfg.iters`,
/// then render the test split into `out/test/`.
pub fn train(
    backend: &mut dyn PlenoxelsBackend,
    data: &Dataset,
    cfg: &PlenoxelsConfig,
    out: &Path,
    start_step: u32,
    show_progress: bool,
) -> Result<(PlenoxelsReport, RenderedSplit)> {
    let mut steps = PlenoxelsSteps {
        cfg,
        upsample_seconds: 0.0,
    };
    let (run, rendered) = steps::run(backend, &mut steps, data, out, start_step, show_progress)?;
    let (res, rows) = backend.shape();
    let report = PlenoxelsReport {
        upsample_seconds: steps.upsample_seconds,
        allocated_vertices: rows,
        bytes_per_vertex: Grid::training_bytes(res, rows) / rows.max(1) as f64,
        run,
    };
    Ok((report, rendered))
}
