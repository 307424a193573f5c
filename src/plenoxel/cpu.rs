//! The CPU stage-1 backend: the kernels' rayon twins over host arrays.

use super::plan::{batch_loss, PlenoxelPass, PlenoxelPlan, TvField};
use super::{
    march_params, state_bytes_of, Gradients, PlenoxelsBackend, PlenoxelsStage, PlenoxelsStepParams,
    PlenoxelsStepStats,
};
use crate::cpu::occupancy::{occupancy_rows, occupancy_slots};
use crate::cpu::plenoxel_fwd::render;
use crate::cpu::plenoxel_train::{train, TrainGrads};
use crate::cpu::plenoxel_weights::max_weights;
use crate::cpu::sample_rays::sample_rays;
use crate::cpu::{rmsprop_sparse, tv, PlenoxelsOptimArrays};
use crate::gpu::{Phase, PhaseClock, StepTiming, TrainRays};
use crate::grid::{Grid, SparseArrays, SH_DIM};
use crate::math::background_msi::BackgroundView;
use crate::math::plenoxel::{GridRef, LossWeights, MarchParams, PlenoxelCounts, OCC_SHIFT_CPU};
use crate::stage::{HostRays, HostSteps, StageBackend, StateFn, StepStore};
use anyhow::{ensure, Result};

/// Grid, occupancy, gradient accumulators and RMSProp state on the host.
pub struct CpuPlenoxels {
    grid: Grid,
    occ: Vec<u32>,
    /// Each row's slot in the links (`occupancy_slots`): the occupancy twin scatters
    /// from the rows.
    slots: Vec<u32>,
    grad_density: Vec<f32>,
    grad_sh: Vec<f32>,
    state_density: Vec<f32>,
    state_sh: Vec<f32>,
    touched: Vec<u32>,
    steps: HostSteps<PlenoxelsStepStats>,
}

impl CpuPlenoxels {
    pub fn new(grid: Grid) -> Self {
        let mut b = CpuPlenoxels {
            grid: grid.clone().without_arrays(),
            occ: Vec::new(),
            slots: Vec::new(),
            grad_density: Vec::new(),
            grad_sh: Vec::new(),
            state_density: Vec::new(),
            state_sh: Vec::new(),
            touched: Vec::new(),
            steps: HostSteps::default(),
        };
        b.load(grid, None).expect("a fresh state always fits");
        b
    }

    fn refresh_occupancy(&mut self) {
        self.occ = occupancy_rows(
            &self.slots,
            &self.grid.density,
            self.grid.res,
            OCC_SHIFT_CPU,
        );
    }

    fn view(&self) -> GridRef<'_> {
        grid_ref(&self.grid, &self.occ)
    }

    /// Run `plan`'s passes in order, the kernels' twins, on the batch `rays`, `targets`; returns
    /// the training pass's per-ray squared errors and counters.
    fn run_plan(
        &mut self,
        plan: &PlenoxelPlan,
        rays: &[f32],
        targets: &[f32],
    ) -> Result<(Vec<f32>, PlenoxelCounts)> {
        let mut out = Default::default();
        for pass in plan.passes() {
            match pass {
                PlenoxelPass::Occupancy => self.refresh_occupancy(),
                PlenoxelPass::Train { stop_thresh, loss } => {
                    let (view, background, spheres) = self.steps.train_grads();
                    let grads = TrainGrads {
                        density: &mut self.grad_density,
                        sh: &mut self.grad_sh,
                        touched: &mut self.touched,
                        background,
                        spheres,
                    };
                    out = data_term(
                        &grid_ref(&self.grid, &self.occ),
                        &march_params(&self.grid, *stop_thresh),
                        rays,
                        targets,
                        *loss,
                        &view,
                        grads,
                    )?;
                }
                PlenoxelPass::Tv { field, chunk } => {
                    let g = &self.grid;
                    let (data, grad) = match field {
                        TvField::Density => (&g.density, &mut self.grad_density),
                        TvField::Sh => (&g.sh, &mut self.grad_sh),
                    };
                    tv(&g.links, data, grad, &mut self.touched, chunk);
                }
                PlenoxelPass::RmsProp(h) => rmsprop_sparse(
                    PlenoxelsOptimArrays {
                        density: &mut self.grid.density,
                        sh: &mut self.grid.sh,
                        grad_density: &mut self.grad_density,
                        grad_sh: &mut self.grad_sh,
                        state_density: &mut self.state_density,
                        state_sh: &mut self.state_sh,
                    },
                    &mut self.touched,
                    h,
                ),
                PlenoxelPass::Background(s) => self.steps.step_background(s),
            }
        }
        Ok(out)
    }
}

fn grid_ref<'a>(grid: &'a Grid, occ: &'a [u32]) -> GridRef<'a> {
    GridRef {
        res: grid.res,
        links: &grid.links,
        density: &grid.density,
        sh: &grid.sh,
        occ,
        occ_shift: OCC_SHIFT_CPU,
    }
}

/// The data term (MSE) pass shared by `step` and `gradients`: per-ray squared error and counters.
fn data_term(
    g: &GridRef,
    mp: &MarchParams,
    rays: &[f32],
    targets: &[f32],
    loss: LossWeights,
    bg: &BackgroundView,
    grads: TrainGrads,
) -> Result<(Vec<f32>, PlenoxelCounts)> {
    let n = rays.len() / 6;
    ensure!(
        n > 0 && targets.len() == 3 * n,
        "batch of {n} rays with {} targets",
        targets.len() / 3
    );
    Ok(train(g, rays, targets, mp, loss, bg, grads))
}

impl StageBackend<PlenoxelsStage> for CpuPlenoxels {
    fn store(&self) -> &dyn StepStore<PlenoxelsStepStats> {
        &self.steps
    }

    fn store_mut(&mut self) -> &mut dyn StepStore<PlenoxelsStepStats> {
        &mut self.steps
    }

    fn submit(&mut self, src: TrainRays, p: &PlenoxelsStepParams) -> Result<()> {
        let mut clock = PhaseClock::start();
        let batch = HostRays::of(src, &mut clock, sample_rays)?;
        let n = batch.rays.len() / 6;
        let plan = PlenoxelPlan::step(p, self.grid.res, n, self.steps.bg.learned())?;
        let (loss, counts) = self.run_plan(&plan, &batch.rays, &batch.targets)?;
        let mse = loss.iter().map(|&l| l as f64).sum::<f64>() / (3 * loss.len()) as f64;
        clock.mark(Phase::Compute);
        self.steps.push(PlenoxelsStepStats {
            mse,
            counts,
            timing: StepTiming {
                host: clock.times,
                ..Default::default()
            },
        });
        Ok(())
    }

    fn grid(&self) -> Result<Grid> {
        Ok(self.grid.clone())
    }

    fn optimizer_state(&self) -> Result<[Vec<f32>; 2]> {
        Ok([self.state_density.clone(), self.state_sh.clone()])
    }

    fn state_bytes(&self) -> u64 {
        state_bytes_of(self.shape())
    }

    fn with_state(&self, f: &mut StateFn<PlenoxelsStage>) -> Result<()> {
        f(&self.grid, &[&self.state_density, &self.state_sh])
    }

    fn load_state(&mut self, state: [Vec<f32>; 2]) -> Result<()> {
        let n = self.grid.allocated();
        let [sd, ss] = state;
        ensure!(
            sd.len() == n && ss.len() == n * SH_DIM,
            "optimizer state of {} + {} floats does not match the grid's {n} vertices",
            sd.len(),
            ss.len()
        );
        self.state_density = sd;
        self.state_sh = ss;
        Ok(())
    }

    fn load(&mut self, grid: Grid, state: Option<[Vec<f32>; 2]>) -> Result<()> {
        let n = grid.allocated();
        self.grad_density = vec![0.0; n];
        self.grad_sh = vec![0.0; n * SH_DIM];
        self.state_density = vec![0.0; n];
        self.state_sh = vec![0.0; n * SH_DIM];
        self.touched = vec![0; n];
        self.slots = occupancy_slots(&grid.links, n);
        self.grid = grid;
        self.refresh_occupancy();
        state.map_or(Ok(()), |s| self.load_state(s))
    }
}

impl PlenoxelsBackend for CpuPlenoxels {
    fn gradients(
        &mut self,
        rays: &[f32],
        targets: &[f32],
        stop_thresh: f32,
        sparsity: f32,
    ) -> Result<Gradients> {
        self.refresh_occupancy();
        let n = self.grid.allocated();
        let (mut density, mut sh, mut touched) = (vec![0.0; n], vec![0.0; n * SH_DIM], vec![0; n]);
        let mut background = [0.0; 3];
        let st = &self.steps;
        let learned_spheres = st.spheres.as_ref().is_some_and(|s| s.learned());
        let mut spheres = vec![
            0.0;
            if learned_spheres {
                st.sphere_grad.len()
            } else {
                0
            }
        ];
        let grads = TrainGrads {
            density: &mut density,
            sh: &mut sh,
            touched: &mut touched,
            background: st.bg.learned().then_some(&mut background),
            spheres: learned_spheres.then_some(&mut spheres[..]),
        };
        let (ray_loss, counts) = data_term(
            &grid_ref(&self.grid, &self.occ),
            &march_params(&self.grid, stop_thresh),
            rays,
            targets,
            batch_loss(rays.len() / 6, sparsity),
            &st.view(),
            grads,
        )?;
        Ok(Gradients {
            ray_loss,
            density,
            sh,
            background,
            spheres,
            counts,
        })
    }

    fn render(&mut self, rays: &[f32], stop_thresh: f32) -> Result<(Vec<f32>, PlenoxelCounts)> {
        self.refresh_occupancy();
        let mp = march_params(&self.grid, stop_thresh);
        Ok(render(&self.view(), rays, &mp, &self.steps.view()))
    }

    fn max_weights(&mut self, rays: &[f32], stop_thresh: f32) -> Result<Vec<f32>> {
        self.refresh_occupancy();
        let mp = march_params(&self.grid, stop_thresh);
        Ok(max_weights(&self.view(), rays, &mp))
    }

    fn shape(&self) -> ([u32; 3], usize) {
        (self.grid.res, self.grid.allocated())
    }
}
