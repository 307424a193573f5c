//! The CPU stage-2 backend: the kernels' twins on a host-resident surface grid.

use super::plan::{PlanGrid, SurfacePass, SurfacePlan};
use super::{
    surface_params, BlockRefresh, SurfaceBackend, SurfaceStage, SurfaceStepParams, SurfaceStepStats,
};
use crate::abi::buffers::SurfCounts;
use crate::abi::buffers::{RayLoss, TrainCounts};
use crate::abi::normal_reg::NormalPrefix;
use crate::abi::regularisers::{axis_neighbours, forward_reach};
use crate::abi::surface_grid::SurfaceGridRef;
use crate::cpu::sample_rays::sample_rays;
use crate::cpu::surface_blocks::SkipAllocation;
use crate::cpu::surface_delta_tv::delta_tv;
use crate::cpu::surface_fwd::render;
use crate::cpu::surface_opacity_reg::surface_opacity_reg;
use crate::cpu::surface_reg::{normal_reg_passes, NormalScratch};
use crate::cpu::surface_train::{train, SurfaceGrads, TrainInput};
use crate::cpu::{surface_rmsprop, tv, SurfaceOptimArrays};
use crate::gpu::{Phase, PhaseClock, StepTiming, TrainRays};
use crate::grid::row_slots;
use crate::grid::state_bytes;
use crate::grid::surface::SurfaceGrid;
use crate::grid::SH_DIM;
use crate::math::surface::Truncation;
use crate::math::surface_blocks::{SkipRef, SURF_BLOCK_SHIFT_CPU};
use crate::stage::{HostRays, HostSteps, StageBackend, StateFn, StepStore};
use anyhow::{ensure, Result};

/// The grid for the kernels' twins, whose links [`CpuSurface::new`] checked (they never change
/// here): the passes skip the O(n³) range check.
fn grid_ref(grid: &SurfaceGrid) -> SurfaceGridRef<'_> {
    SurfaceGridRef {
        links_checked: true,
        ..grid.as_ref()
    }
}

/// Host-resident stage-2 state.
pub struct CpuSurface {
    grid: SurfaceGrid,
    grad: [Vec<f32>; 3],
    state: [Vec<f32>; 3],
    touched: Vec<u32>,
    /// Per-grid neighbour tables: Lδ's axis neighbours (and their forward reach in rows), and
    /// the normal regulariser's data (neighbour table, cell counts of the chunks).
    axis_nbrs: Vec<i32>,
    axis_reach: u32,
    normals: NormalPrefix,
    /// The regularisers' per-row arrays, kept between steps (each pass writes only its
    /// chunk's rows): Lδ's q, the normal regularisers' normals and corners.
    delta_dirs: Vec<f32>,
    normal_scratch: NormalScratch,
    /// The block masks the walks skip with, what of them the allocation fixes, and when to
    /// rebuild them.
    blocks: Vec<u32>,
    skip: SkipAllocation,
    refresh: BlockRefresh,
    steps: HostSteps<SurfaceStepStats>,
}

impl CpuSurface {
    /// The backend on `grid`, after checking it (`SurfaceGrid::validate`).
    pub fn new(grid: SurfaceGrid) -> Result<Self> {
        grid.validate()?;
        let n = grid.delta.len();
        let row_slot = row_slots(&grid.links, n);
        let normals = NormalPrefix::new(&grid.links, &row_slot, grid.res);
        let axis_nbrs = axis_neighbours(&grid.links, &row_slot, grid.res);
        Ok(CpuSurface {
            axis_reach: forward_reach(&axis_nbrs),
            axis_nbrs,
            normals,
            delta_dirs: Vec::new(),
            normal_scratch: NormalScratch::default(),
            blocks: Vec::new(),
            skip: SkipAllocation::new(&grid.links, grid.res[0], SURF_BLOCK_SHIFT_CPU)?,
            refresh: BlockRefresh::default(),
            grid,
            grad: [vec![0.0; n], vec![0.0; n], vec![0.0; n * SH_DIM]],
            state: [vec![0.0; n], vec![0.0; n], vec![0.0; n * SH_DIM]],
            touched: vec![0; n],
            steps: HostSteps::default(),
        })
    }

    /// Rebuild the block masks when δ may have drifted past their margin.
    fn refresh_blocks(&mut self, lr_delta: f32, beta: f32) -> Result<()> {
        if let Some(margin) = self.refresh.before_pass(lr_delta, beta) {
            self.build_blocks(margin)?;
        }
        Ok(())
    }

    fn build_blocks(&mut self, margin: f32) -> Result<()> {
        let g = &self.grid;
        self.blocks = self.skip.build(&g.links, &g.delta, &g.levels, margin)?;
        Ok(())
    }

    /// The plan of a step with `p` on `n_rays` rays.
    fn plan(&mut self, p: &SurfaceStepParams, n_rays: usize) -> Result<SurfacePlan> {
        let g = PlanGrid {
            res: self.grid.res,
            rows: self.grid.delta.len() as u32,
            normals: &self.normals,
            delta_reach: self.axis_reach,
        };
        SurfacePlan::step(p, &g, n_rays, self.steps.bg.learned(), &mut self.refresh)
    }

    /// Run `plan`'s passes in order, the kernels' twins, on the batch `rays`, `targets` (with
    /// per-ray importance `weights`, if any).
    fn run_plan(
        &mut self,
        plan: &SurfacePlan,
        rays: &[f32],
        targets: &[f32],
        weights: Option<&[f32]>,
    ) -> Result<PassOutput> {
        let mut out = PassOutput::default();
        for pass in plan.passes() {
            match pass {
                SurfacePass::Blocks { margin } => self.build_blocks(*margin)?,
                SurfacePass::Train {
                    truncation,
                    stop_thresh,
                    loss,
                } => {
                    let bg = &mut self.steps.bg;
                    let sp = surface_params(&self.grid, *truncation, *stop_thresh, bg.rgb)
                        .with_spheres(self.steps.spheres.clone());
                    let [gd, go, gs] = &mut self.grad;
                    (out.losses, out.counts) = train(
                        &grid_ref(&self.grid),
                        TrainInput {
                            rays,
                            targets,
                            weights,
                        },
                        &sp,
                        loss,
                        Some(SkipRef {
                            words: &self.blocks,
                            shift: SURF_BLOCK_SHIFT_CPU,
                        }),
                        SurfaceGrads {
                            delta: gd,
                            opacity: go,
                            sh: gs,
                            touched: &mut self.touched,
                            background: bg.learned().then_some(&mut bg.grad),
                        },
                    )?;
                }
                SurfacePass::DeltaTv(c) => delta_tv(
                    &self.axis_nbrs,
                    &self.grid.delta,
                    &mut self.grad[0],
                    c,
                    self.axis_reach,
                    &mut self.delta_dirs,
                ),
                SurfacePass::OpacityTv(c) => tv(
                    &self.grid.links,
                    &self.grid.opacity,
                    &mut self.grad[1],
                    &mut self.touched,
                    c,
                ),
                SurfacePass::OpacityLog(c) => {
                    out.reg_loss += surface_opacity_reg(&self.grid.opacity, &mut self.grad[1], c);
                }
                SurfacePass::Normals(c) => {
                    out.reg_loss += normal_reg_passes(
                        &self.normals,
                        &self.grid.delta,
                        &mut self.grad[0],
                        &mut self.touched,
                        c,
                        &mut self.normal_scratch,
                    )
                    .loss;
                }
                SurfacePass::RmsProp(h) => {
                    let [gd, go, gs] = &mut self.grad;
                    let [sd, so, ss] = &mut self.state;
                    let g = &mut self.grid;
                    surface_rmsprop(
                        SurfaceOptimArrays {
                            delta: &mut g.delta,
                            opacity: &mut g.opacity,
                            sh: &mut g.sh,
                            grad_delta: gd,
                            grad_opacity: go,
                            grad_sh: gs,
                            state_delta: sd,
                            state_opacity: so,
                            state_sh: ss,
                        },
                        &mut self.touched,
                        h,
                    );
                }
                SurfacePass::Background(s) => self.steps.step_background(s),
            }
        }
        Ok(out)
    }

    /// One training step on `batch`; `clock` has the step's host time so far.
    fn step_on(
        &mut self,
        batch: &HostRays,
        p: &SurfaceStepParams,
        mut clock: PhaseClock,
    ) -> Result<SurfaceStepStats> {
        let n = batch.rays.len() / 6;
        let plan = self.plan(p, n)?;
        let weights = batch.weights.as_deref();
        let PassOutput {
            losses,
            counts,
            reg_loss,
        } = self.run_plan(&plan, &batch.rays, &batch.targets, weights)?;
        self.refresh.after_update(p.lr_delta, p.beta);
        let nf = n.max(1) as f64;
        let mut stats = SurfaceStepStats {
            mse: losses.iter().map(|l| l.sq_err as f64).sum::<f64>() / (3.0 * nf),
            entropy: losses.iter().map(|l| l.entropy as f64).sum::<f64>() / nf,
            consistency: losses.iter().map(|l| l.consistency as f64).sum::<f64>() / nf,
            reg_loss,
            counts,
            timing: StepTiming::default(),
        };
        clock.mark(Phase::Compute);
        stats.timing.host = clock.times;
        Ok(stats)
    }
}

/// What a step's passes produce on the CPU: the training pass's per-ray losses and counters,
/// and the Lα + Ln loss.
#[derive(Default)]
struct PassOutput {
    losses: Vec<RayLoss>,
    counts: TrainCounts,
    reg_loss: f64,
}

impl StageBackend<SurfaceStage> for CpuSurface {
    fn store(&self) -> &dyn StepStore<SurfaceStepStats> {
        &self.steps
    }

    fn store_mut(&mut self) -> &mut dyn StepStore<SurfaceStepStats> {
        &mut self.steps
    }

    fn submit(&mut self, src: TrainRays, p: &SurfaceStepParams) -> Result<()> {
        let mut clock = PhaseClock::start();
        let batch = HostRays::of(src, &mut clock, sample_rays)?;
        let stats = self.step_on(&batch, p, clock)?;
        self.steps.push(stats);
        Ok(())
    }

    fn grid(&self) -> Result<SurfaceGrid> {
        Ok(self.grid.clone())
    }

    fn optimizer_state(&self) -> Result<[Vec<f32>; 3]> {
        Ok(self.state.clone())
    }

    fn state_bytes(&self) -> u64 {
        let g = &self.grid;
        state_bytes(
            g.links.len() as u64,
            g.delta.len() as u64,
            2 + SH_DIM as u64,
        )
    }

    fn with_state(&self, f: &mut StateFn<SurfaceStage>) -> Result<()> {
        let [sd, so, ss] = &self.state;
        f(&self.grid, &[sd, so, ss])
    }

    fn load_state(&mut self, state: [Vec<f32>; 3]) -> Result<()> {
        let n = self.grid.delta.len();
        ensure!(
            state[0].len() == n && state[1].len() == n && state[2].len() == n * SH_DIM,
            "optimizer state of {:?} floats does not match the surface grid's {n} vertices",
            state.each_ref().map(|s| s.len())
        );
        self.state = state;
        Ok(())
    }

    fn load(&mut self, grid: SurfaceGrid, state: Option<[Vec<f32>; 3]>) -> Result<()> {
        let steps = std::mem::take(&mut self.steps);
        *self = CpuSurface::new(grid)?;
        self.steps = steps;
        state.map_or(Ok(()), |s| self.load_state(s))
    }
}

impl SurfaceBackend for CpuSurface {
    fn render(
        &mut self,
        rays: &[f32],
        truncation: Truncation,
        stop_thresh: f32,
    ) -> Result<(Vec<f32>, SurfCounts)> {
        let sp = surface_params(&self.grid, truncation, stop_thresh, self.steps.bg.rgb)
            .with_spheres(self.steps.spheres.clone());
        self.refresh_blocks(0.0, 0.0)?;
        let skip = SkipRef {
            words: &self.blocks,
            shift: SURF_BLOCK_SHIFT_CPU,
        };
        let (out, counts) = render(&grid_ref(&self.grid), rays, &sp, Some(skip))?;
        Ok((out.iter().flat_map(|o| o.rgb).collect(), counts))
    }
}
