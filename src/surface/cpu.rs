//! The CPU stage-2 backend: the kernels' twins on a host-resident surface grid.

use super::{
    batch_loss, surface_params, SurfaceBackend, SurfaceState, SurfaceStepParams, SurfaceStepStats,
};
use crate::cpu::rmsprop_one;
use crate::cpu::surface_fwd::{render, SurfCounts};
use crate::cpu::surface_train::{train, SurfaceGrads};
use crate::cpu::{tv, TvChunk};
use crate::grid::surface::SurfaceGrid;
use crate::grid::SH_DIM;
use anyhow::{ensure, Result};
use rayon::prelude::*;

/// Host-resident stage-2 state.
pub struct CpuSurface {
    grid: SurfaceGrid,
    grad: [Vec<f32>; 3],
    state: SurfaceState,
    touched: Vec<u32>,
}

impl CpuSurface {
    pub fn new(grid: SurfaceGrid) -> Self {
        let n = grid.delta.len();
        CpuSurface {
            grid,
            grad: [vec![0.0; n], vec![0.0; n], vec![0.0; n * SH_DIM]],
            state: [vec![0.0; n], vec![0.0; n], vec![0.0; n * SH_DIM]],
            touched: vec![0; n],
        }
    }

    /// The per-vertex regularisers' gradients.
    fn regularise(&mut self, p: &SurfaceStepParams) -> Result<()> {
        let g = &self.grid;
        let slots = g.links.len() as u32;
        if let Some(lambda) = p.regs.delta_tv {
            // κ·√(|d|² + ε/κ²) = √(|κd|² + ε): the N/256-scaled TV up to ε.
            let kappa = g.res[0] as f32 / 256.0;
            let count = g.delta.len().max(1) as f32;
            tv(
                &g.links,
                &g.delta,
                &mut self.grad[0],
                &mut self.touched,
                &TvChunk {
                    res: g.res,
                    start: 0,
                    count: slots,
                    channels: 1,
                    scale: lambda * kappa / count,
                },
            );
        }
        if let Some((start, count, lambda)) = p.regs.opacity_tv {
            tv(
                &g.links,
                &g.opacity,
                &mut self.grad[1],
                &mut self.touched,
                &TvChunk {
                    res: g.res,
                    start,
                    count,
                    channels: 1,
                    scale: lambda / count.max(1) as f32,
                },
            );
        }
        ensure!(
            p.regs.opacity_log.is_none() && p.regs.normals.is_none(),
            "the CPU backend has no Lα / normal regulariser yet"
        );
        Ok(())
    }

    /// RMSProp on every touched vertex (δ, σα, SH), then clear flags and gradients.
    fn optimise(&mut self, p: &SurfaceStepParams) {
        let [gd, go, gs] = &mut self.grad;
        let [sd, so, ss] = &mut self.state;
        let g = &mut self.grid;
        g.delta
            .par_iter_mut()
            .zip(g.opacity.par_iter_mut())
            .zip(g.sh.par_chunks_mut(SH_DIM))
            .zip(gd.par_iter_mut())
            .zip(go.par_iter_mut())
            .zip(gs.par_chunks_mut(SH_DIM))
            .zip(sd.par_iter_mut())
            .zip(so.par_iter_mut())
            .zip(ss.par_chunks_mut(SH_DIM))
            .zip(self.touched.par_iter_mut())
            .for_each(|(((((((((d, o), sh), gd), go), gs), sd), so), ss), t)| {
                if *t == 0 {
                    return;
                }
                *t = 0;
                rmsprop_one(d, gd, sd, p.lr_delta, p.beta, p.eps);
                rmsprop_one(o, go, so, p.lr_opacity, p.beta, p.eps);
                for k in 0..SH_DIM {
                    rmsprop_one(&mut sh[k], &mut gs[k], &mut ss[k], p.lr_sh, p.beta, p.eps);
                }
            });
    }
}

impl SurfaceBackend for CpuSurface {
    fn name(&self) -> &'static str {
        "cpu"
    }

    fn step(
        &mut self,
        rays: &[f32],
        targets: &[f32],
        p: &SurfaceStepParams,
    ) -> Result<SurfaceStepStats> {
        let sp = surface_params(&self.grid, p.a, p.stop_thresh);
        let n = rays.len() / 6;
        let [gd, go, gs] = &mut self.grad;
        let (losses, counts) = train(
            &self.grid.as_ref(),
            rays,
            targets,
            &sp,
            &batch_loss(n, p),
            SurfaceGrads {
                delta: gd,
                opacity: go,
                sh: gs,
                touched: &mut self.touched,
            },
        )?;
        self.regularise(p)?;
        self.optimise(p);
        let nf = n.max(1) as f64;
        Ok(SurfaceStepStats {
            mse: losses.iter().map(|l| l.sq_err as f64).sum::<f64>() / (3.0 * nf),
            entropy: losses.iter().map(|l| l.entropy as f64).sum::<f64>() / nf,
            consistency: losses.iter().map(|l| l.consistency as f64).sum::<f64>() / nf,
            counts,
            device_ns: 0.0,
        })
    }

    fn render(&mut self, rays: &[f32], a: f32, stop_thresh: f32) -> Result<(Vec<f32>, SurfCounts)> {
        let sp = surface_params(&self.grid, a, stop_thresh);
        let (out, counts) = render(&self.grid.as_ref(), rays, &sp)?;
        Ok((out.iter().flat_map(|o| o.rgb).collect(), counts))
    }

    fn grid(&self) -> Result<SurfaceGrid> {
        Ok(self.grid.clone())
    }

    fn optimizer_state(&self) -> Result<SurfaceState> {
        Ok(self.state.clone())
    }

    fn load(&mut self, grid: SurfaceGrid, state: Option<SurfaceState>) -> Result<()> {
        let n = grid.delta.len();
        let state = state.unwrap_or_else(|| [vec![0.0; n], vec![0.0; n], vec![0.0; n * SH_DIM]]);
        ensure!(
            state[0].len() == n && state[1].len() == n && state[2].len() == n * SH_DIM,
            "optimizer state does not match the surface grid"
        );
        *self = CpuSurface::new(grid);
        self.state = state;
        Ok(())
    }
}
