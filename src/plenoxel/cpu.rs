//! The CPU stage-1 backend: the kernels' rayon twins over host arrays.

use super::{march_params, Gradients, Plenoxels, StepParams, StepStats};
use crate::cpu::plenoxel::{self as twin, TrainGrads};
use crate::cpu::{rmsprop, tv, TvChunk};
use crate::grid::{Grid, SH_DIM};
use crate::math::plenoxel::{Counts, GridRef};
use anyhow::{ensure, Result};

/// Grid, occupancy, gradient accumulators and RMSProp state on the host.
pub struct CpuPlenoxels {
    grid: Grid,
    occ: Vec<u32>,
    grad_density: Vec<f32>,
    grad_sh: Vec<f32>,
    state_density: Vec<f32>,
    state_sh: Vec<f32>,
}

impl CpuPlenoxels {
    pub fn new(grid: Grid) -> Self {
        let mut b = CpuPlenoxels {
            grid: Grid {
                links: Vec::new(),
                density: Vec::new(),
                sh: Vec::new(),
                ..grid.clone()
            },
            occ: Vec::new(),
            grad_density: Vec::new(),
            grad_sh: Vec::new(),
            state_density: Vec::new(),
            state_sh: Vec::new(),
        };
        b.load(grid, None).expect("a fresh state always fits");
        b
    }

    fn refresh_occupancy(&mut self) {
        self.occ = twin::occupancy(&self.grid.links, &self.grid.density, self.grid.res);
    }

    fn view(&self) -> GridRef<'_> {
        GridRef {
            res: self.grid.res,
            links: &self.grid.links,
            density: &self.grid.density,
            sh: &self.grid.sh,
            occ: &self.occ,
        }
    }
}

impl Plenoxels for CpuPlenoxels {
    fn name(&self) -> &'static str {
        "cpu"
    }

    fn step(&mut self, rays: &[f32], targets: &[f32], p: &StepParams) -> Result<StepStats> {
        let n = rays.len() / 6;
        ensure!(
            n > 0 && targets.len() == 3 * n,
            "batch of {n} rays with {} targets",
            targets.len() / 3
        );
        self.refresh_occupancy();
        let mp = march_params(&self.grid, p.stop_thresh);
        let view = GridRef {
            res: self.grid.res,
            links: &self.grid.links,
            density: &self.grid.density,
            sh: &self.grid.sh,
            occ: &self.occ,
        };
        let (loss, counts) = twin::train(
            &view,
            rays,
            targets,
            &mp,
            2.0 / (3.0 * n as f32),
            TrainGrads {
                density: &mut self.grad_density,
                sh: &mut self.grad_sh,
            },
        );
        if let Some(t) = p.tv {
            let chunk = |channels: u32, lambda: f32| TvChunk {
                res: self.grid.res,
                start: t.start,
                count: t.count,
                channels,
                scale: lambda / t.count.max(1) as f32,
            };
            tv(
                &self.grid.links,
                &self.grid.density,
                &mut self.grad_density,
                &chunk(1, t.lambda_sigma),
            );
            tv(
                &self.grid.links,
                &self.grid.sh,
                &mut self.grad_sh,
                &chunk(SH_DIM as u32, t.lambda_sh),
            );
        }
        rmsprop(
            &mut self.grid.density,
            &mut self.grad_density,
            &mut self.state_density,
            p.lr_sigma,
            p.beta,
            p.eps,
        );
        rmsprop(
            &mut self.grid.sh,
            &mut self.grad_sh,
            &mut self.state_sh,
            p.lr_sh,
            p.beta,
            p.eps,
        );
        let mse = loss.iter().map(|&l| l as f64).sum::<f64>() / (3 * n) as f64;
        Ok(StepStats {
            mse,
            counts,
            device_ns: 0.0,
        })
    }

    fn gradients(&mut self, rays: &[f32], targets: &[f32], stop_thresh: f32) -> Result<Gradients> {
        let n = rays.len() / 6;
        ensure!(
            n > 0 && targets.len() == 3 * n,
            "batch of {n} rays with {} targets",
            targets.len() / 3
        );
        self.refresh_occupancy();
        let mp = march_params(&self.grid, stop_thresh);
        let mut density = vec![0.0; self.grid.allocated()];
        let mut sh = vec![0.0; self.grid.allocated() * SH_DIM];
        let (ray_loss, counts) = twin::train(
            &self.view(),
            rays,
            targets,
            &mp,
            2.0 / (3.0 * n as f32),
            TrainGrads {
                density: &mut density,
                sh: &mut sh,
            },
        );
        Ok(Gradients {
            ray_loss,
            density,
            sh,
            counts,
        })
    }

    fn render(&mut self, rays: &[f32], stop_thresh: f32) -> Result<(Vec<f32>, Counts)> {
        self.refresh_occupancy();
        let mp = march_params(&self.grid, stop_thresh);
        Ok(twin::render(&self.view(), rays, &mp))
    }

    fn max_weights(&mut self, rays: &[f32], stop_thresh: f32) -> Result<Vec<f32>> {
        self.refresh_occupancy();
        let mp = march_params(&self.grid, stop_thresh);
        Ok(twin::max_weights(&self.view(), rays, &mp))
    }

    fn grid(&self) -> Result<Grid> {
        Ok(self.grid.clone())
    }

    fn optimizer_state(&self) -> Result<(Vec<f32>, Vec<f32>)> {
        Ok((self.state_density.clone(), self.state_sh.clone()))
    }

    fn load(&mut self, grid: Grid, state: Option<(Vec<f32>, Vec<f32>)>) -> Result<()> {
        let n = grid.allocated();
        let (sd, ss) = state.unwrap_or_else(|| (vec![0.0; n], vec![0.0; n * SH_DIM]));
        ensure!(
            sd.len() == n && ss.len() == n * SH_DIM,
            "optimizer state does not match the grid"
        );
        self.grad_density = vec![0.0; n];
        self.grad_sh = vec![0.0; n * SH_DIM];
        self.state_density = sd;
        self.state_sh = ss;
        self.grid = grid;
        self.refresh_occupancy();
        Ok(())
    }
}
