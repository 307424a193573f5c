//! Stage 2 (αSurf) in the training loop ([`super::steps`]): the scheduled learning rates,
//! truncation and regularisers of each step; at the end the surfaces that cannot reach
//! α ≥ `prune_alpha` are dropped before the last checkpoint and the test renders.

use super::render::{render_split_with, RenderedSplit};
use super::steps::{self, LoopReport, StageSteps};
use super::surface_config::SurfaceConfig;
use crate::abi::buffers::TrainPerRay;
use crate::abi::regularisers::{delta_tv_chunk, opacity_tv_chunk, OpacityChunk};
use crate::data::{Dataset, TrainViews};
use crate::math::surface::Truncation;
use crate::surface::{SurfaceBackend, SurfaceRegs, SurfaceStage, SurfaceStepParams};
use anyhow::{bail, Result};
use rand::Rng;
use rand_pcg::Pcg64;
use std::path::Path;

/// A finished stage-2 run: the loop's figures (per training ray: the training pass's counters,
/// `TrainCounts`) and the vertices before and after the pruning.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct SurfaceReport {
    pub run: LoopReport<TrainPerRay>,
    pub vertices_before_prune: usize,
    pub allocated_vertices: usize,
}

/// The scheduled parameters of step `step`, with `truncation`, for a grid of resolution `res`
/// with `rows` allocated vertices; `draws` place the random regulariser chunks (Lα's start, Ln's
/// and Lδ's start — one row for both, so that the δ rows RMSProp updates densely cover both —
/// and TVα's draw).
pub fn step_params(
    cfg: &SurfaceConfig,
    res: [u32; 3],
    rows: u32,
    step: u32,
    truncation: Truncation,
    draws: [u64; 3],
) -> SurfaceStepParams {
    let row_chunk = |fraction: f32, draw: u64| {
        let count = ((rows as f32 * fraction) as u32).clamp(1, rows.max(1));
        ((draw % rows.max(1) as u64) as u32, count)
    };
    let (la_start, la_count) = row_chunk(cfg.alpha_fraction, draws[0]);
    let (n_start, n_count) = row_chunk(cfg.normal_fraction, draws[1]);
    let tv_draw = draws[2];
    let (ln1, ln2) = (cfg.lambda_n1.at(step), cfg.lambda_n2);
    SurfaceStepParams {
        lr_delta: cfg.lr_delta.at(step),
        lr_opacity: cfg.lr_opacity.at(step),
        lr_sh: cfg.lr_sh.at(step),
        // A learned background is a colour, as the SH are: it steps at their rate.
        lr_bg: cfg.lr_sh.at(step),
        beta: cfg.beta,
        eps: cfg.eps,
        truncation,
        stop_thresh: cfg.stop_thresh,
        lambda_h: cfg.lambda_h,
        lambda_c: if step < cfg.lambda_c_until {
            cfg.lambda_c
        } else {
            0.0
        },
        regs: SurfaceRegs {
            delta_tv: (cfg.lambda_delta > 0.0 && rows > 0)
                .then(|| delta_tv_chunk(res, rows, cfg.delta_fraction, cfg.lambda_delta, draws[1])),
            opacity_tv: (cfg.lambda_tv_alpha > 0.0).then(|| {
                opacity_tv_chunk(res, cfg.tv_alpha_fraction, cfg.lambda_tv_alpha, tv_draw)
            }),
            opacity_log: (cfg.lambda_alpha > 0.0).then_some(OpacityChunk {
                rows,
                start: la_start,
                count: la_count,
                lambda: cfg.lambda_alpha,
            }),
            normals: (ln1 > 0.0 || ln2 > 0.0).then_some((n_start, n_count, ln1, ln2)),
        },
    }
}

/// Stage 2's part of a run: its configuration, the grid's shape the regulariser chunks are drawn
/// over, and the vertices before and after the pruning.
pub struct SurfaceSteps<'a> {
    pub cfg: &'a SurfaceConfig,
    res: [u32; 3],
    rows: u32,
    vertices_before_prune: usize,
    allocated_vertices: usize,
}

/// Stage 2's part of the loop.
impl<'b> StageSteps<SurfaceStage, dyn SurfaceBackend + 'b> for SurfaceSteps<'_> {
    type Config = SurfaceConfig;

    fn config(&self) -> &SurfaceConfig {
        self.cfg
    }

    fn views<'d>(&self, data: &'d Dataset) -> Result<TrainViews<'d>> {
        TrainViews::new(&data.train, &data.scene)?.focused(self.cfg.ray_focus)
    }

    fn start(
        &mut self,
        backend: &mut (dyn SurfaceBackend + 'b),
        _: &Dataset,
        _: u32,
    ) -> Result<()> {
        let grid = backend.grid()?;
        (self.res, self.rows) = (grid.res, grid.delta.len() as u32);
        Ok(())
    }

    fn params(&mut self, step: u32, rng: &mut Pcg64) -> SurfaceStepParams {
        let draws = [
            rng.random::<u32>().into(),
            rng.random::<u32>().into(),
            rng.random(),
        ];
        let truncation = self.cfg.truncation(step);
        step_params(self.cfg, self.res, self.rows, step, truncation, draws)
    }

    /// Drop the surfaces that cannot reach α ≥ prune_alpha; the optimiser state ends with them.
    fn finish(&mut self, backend: &mut (dyn SurfaceBackend + 'b)) -> Result<()> {
        let mut grid = backend.grid()?;
        self.vertices_before_prune = grid.delta.len();
        grid.prune_transparent(self.cfg.prune_alpha);
        if grid.delta.is_empty() {
            bail!(
                "no surface reaches α ≥ {} after training: nothing left (training diverged?)",
                self.cfg.prune_alpha
            );
        }
        self.allocated_vertices = grid.delta.len();
        backend.load(grid, None)
    }

    fn render_test(
        &mut self,
        backend: &mut (dyn SurfaceBackend + 'b),
        data: &Dataset,
        out: &Path,
    ) -> Result<RenderedSplit> {
        let (cfg, truncation) = (self.cfg, self.cfg.truncation(self.cfg.iters));
        render_split_with(
            &mut |rays| Ok(backend.render(rays, truncation, cfg.stop_thresh)?.0),
            data,
            &data.test,
            out,
            1,
        )
    }
}

/// Train stage 2 from `start_step` to `cfg.iters`, then prune, save and render the test split
/// into `out/test/`.
pub fn train(
    backend: &mut dyn SurfaceBackend,
    data: &Dataset,
    cfg: &SurfaceConfig,
    out: &Path,
    start_step: u32,
    show_progress: bool,
) -> Result<(SurfaceReport, RenderedSplit)> {
    let mut steps = SurfaceSteps {
        cfg,
        res: [0; 3],
        rows: 0,
        vertices_before_prune: 0,
        allocated_vertices: 0,
    };
    let (run, rendered) = steps::run(backend, &mut steps, data, out, start_step, show_progress)?;
    let report = SurfaceReport {
        run,
        vertices_before_prune: steps.vertices_before_prune,
        allocated_vertices: steps.allocated_vertices,
    };
    Ok((report, rendered))
}
