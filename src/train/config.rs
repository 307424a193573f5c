//! Stage-1 configuration and its presets: `paper` (the svox2 synthetic schedule) and `fast` (a
//! schedule sized for a 2-core CPU running lavapipe). Both go through the same trainer.

use super::preset::Preset;
use super::schedule::DelayedExp;
use super::steps::{loop_schedule, LoopSchedule, Scheduled};
use crate::plenoxel::{PlenoxelsStepParams, TvParams};
use serde::{Deserialize, Serialize};

/// The presets' least time between periodic checkpoints (both stages), in seconds.
pub const CHECKPOINT_MIN_SECONDS: f32 = 60.0;

/// The grid resolutions a new run may ask for (`--res`, and `res` / `upsample` in
/// `--plenoxels-set`).
pub const GRID_RES: std::ops::RangeInclusive<u32> = 8..=1024;

/// Both presets' weight of the TV on the background's spheres: none. svox2's `tnt` weight (1e-3,
/// a mean over the texels as here) and 1e-2 leave the development capture's geometry where it is
/// (docs/tuning.md), so the regulariser is there for `--plenoxels-set tv_background=…`.
const TV_BACKGROUND: f32 = 0.0;

/// Both presets' weight of the sparsity loss: none (docs/tuning.md).
const SPARSITY: f32 = 0.0;

/// The largest final grid at which `fast`'s stage 1 keeps its batch of rays per step.
const FAST_BATCH_RES: u64 = 128;

/// Everything that shapes a stage-1 run; stored in checkpoints and metrics.json.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlenoxelsConfig {
    pub preset: Preset,
    /// Grid resolution at the start.
    pub res: u32,
    /// (step, new resolution): upsample with weight pruning at these steps.
    pub upsample: Vec<(u32, u32)>,
    pub iters: u32,
    /// Rays per batch.
    pub batch: u32,
    pub lr_sigma: DelayedExp,
    pub lr_sh: DelayedExp,
    pub tv_sigma: f32,
    pub tv_sh: f32,
    /// Fraction of the vertex slots in each step's TV chunk.
    pub tv_fraction: f32,
    /// Switch TV off after the first upsample (the paper set-up).
    pub tv_until_upsample: bool,
    /// Weight of the TV on the background's spheres (`--background spheres`), over every texel
    /// at every step (σ and colour alike, as svox2's `tnt` weights; 0: none, as in
    /// configurations saved before it).
    #[serde(default)]
    pub tv_background: f32,
    /// λ of svox2's Cauchy sparsity loss λ·Σ log(1 + 2σ²) over every shaded sample of the
    /// training rays (its `lambda_sparsity`; 0: none, as in configurations saved before it).
    #[serde(default)]
    pub sparsity: f32,
    /// σ of the initial grid's vertices (`grid::InitialFill`).
    pub init_sigma: f32,
    /// Early ray termination: stop when transmittance falls below this.
    pub stop_thresh: f32,
    /// Keep vertices whose max training-ray weight reaches this when upsampling.
    pub prune_weight: f32,
    /// Transmittance stop of the pruning-weight render.
    pub prune_stop_thresh: f32,
    /// Use every k-th pixel (per axis) of the training views for the pruning-weight render.
    pub prune_pixel_stride: u32,
    pub beta: f32,
    pub eps: f32,
    /// Write a checkpoint every this many steps (and at the end)…
    pub checkpoint_every: u32,
    /// …once at least this many seconds have passed since the last one (or the start): a run
    /// that takes seconds on a GPU does not stop to copy its state every few hundred steps.
    /// 0: exactly every `checkpoint_every` steps (and in configurations saved before it).
    #[serde(default)]
    pub checkpoint_min_seconds: f32,
    pub seed: u64,
}

impl PlenoxelsConfig {
    /// svox2's synthetic schedule: 256³ → 512³ at 38.4k steps, 128k steps of 5000 rays.
    pub fn paper() -> Self {
        PlenoxelsConfig {
            preset: Preset::Paper,
            res: 256,
            upsample: vec![(38_400, 512)],
            iters: 128_000,
            batch: 5000,
            lr_sigma: DelayedExp {
                init: 30.0,
                last: 0.05,
                max_steps: 250_000,
                delay_steps: 15_000,
                delay_mult: 0.01,
            },
            lr_sh: DelayedExp {
                init: 1e-2,
                last: 5e-6,
                max_steps: 250_000,
                delay_steps: 0,
                delay_mult: 1.0,
            },
            tv_sigma: 1e-5,
            tv_sh: 1e-3,
            tv_fraction: 0.01,
            tv_until_upsample: true,
            tv_background: TV_BACKGROUND,
            sparsity: SPARSITY,
            init_sigma: 0.1,
            stop_thresh: 1e-7,
            prune_weight: 5e-4,
            prune_stop_thresh: 0.2,
            prune_pixel_stride: 1,
            beta: 0.95,
            eps: 1e-8,
            checkpoint_every: 5000,
            checkpoint_min_seconds: CHECKPOINT_MIN_SECONDS,
            seed: 0,
        }
    }

    /// A CPU-sized schedule: 64³ → 128³, a few thousand steps, faster decays (its batch grows
    /// with grids above 128³: [`PlenoxelsConfig::batch_for_grid`]).
    pub fn fast() -> Self {
        PlenoxelsConfig {
            preset: Preset::Fast,
            res: 64,
            upsample: vec![(1000, 128)],
            iters: 3000,
            batch: 4096,
            lr_sigma: DelayedExp {
                init: 30.0,
                last: 0.5,
                max_steps: 3000,
                delay_steps: 300,
                delay_mult: 0.01,
            },
            lr_sh: DelayedExp {
                init: 1e-2,
                last: 1e-3,
                max_steps: 3000,
                delay_steps: 0,
                delay_mult: 1.0,
            },
            tv_sigma: 1e-5,
            tv_sh: 1e-3,
            tv_fraction: 0.01,
            tv_until_upsample: false,
            tv_background: TV_BACKGROUND,
            sparsity: SPARSITY,
            init_sigma: 0.1,
            stop_thresh: 1e-4,
            prune_weight: 5e-4,
            prune_stop_thresh: 0.2,
            prune_pixel_stride: 2,
            beta: 0.95,
            eps: 1e-8,
            checkpoint_every: 500,
            checkpoint_min_seconds: CHECKPOINT_MIN_SECONDS,
            seed: 0,
        }
    }

    /// The parameters of the step after `step` steps, with the TV chunk `tv` (drawn by the
    /// caller).
    pub fn step_params(&self, step: u32, tv: Option<TvParams>) -> PlenoxelsStepParams {
        PlenoxelsStepParams {
            lr_sigma: self.lr_sigma.at(step),
            lr_sh: self.lr_sh.at(step),
            beta: self.beta,
            eps: self.eps,
            stop_thresh: self.stop_thresh,
            tv,
            // A learned background is a colour, as the SH are: it steps at their rate.
            lr_bg: self.lr_sh.at(step),
            tv_background: self.tv_background,
            sparsity: self.sparsity,
        }
    }

    /// The schedule of `preset`; `imported` names no schedule.
    pub fn preset(preset: Preset) -> anyhow::Result<Self> {
        match preset {
            Preset::Paper => Ok(Self::paper()),
            Preset::Fast => Ok(Self::fast()),
            Preset::Imported => anyhow::bail!("preset `imported` has no stage-1 schedule"),
        }
    }

    /// Reject values no run can use (a checkpoint's configuration is checked on resume):
    /// zero batch, checkpoint interval or pixel stride, a grid axis below 2, fractions outside
    /// [0, 1], non-finite thresholds.
    pub fn validate(&self) -> anyhow::Result<()> {
        anyhow::ensure!(
            self.batch > 0 && self.checkpoint_every > 0 && self.prune_pixel_stride > 0,
            "batch, checkpoint_every and prune_pixel_stride must be at least 1"
        );
        anyhow::ensure!(
            self.res >= 2 && self.upsample.iter().all(|u| u.1 >= 2),
            "grid resolutions must be at least 2"
        );
        anyhow::ensure!(
            (0.0..=1.0).contains(&self.tv_fraction),
            "tv_fraction must be in [0, 1], got {}",
            self.tv_fraction
        );
        for (name, v) in [
            ("stop_thresh", self.stop_thresh),
            ("prune_weight", self.prune_weight),
            ("prune_stop_thresh", self.prune_stop_thresh),
            ("tv_sigma", self.tv_sigma),
            ("tv_sh", self.tv_sh),
            ("tv_background", self.tv_background),
            ("sparsity", self.sparsity),
            ("beta", self.beta),
            ("eps", self.eps),
            ("init_sigma", self.init_sigma),
            ("checkpoint_min_seconds", self.checkpoint_min_seconds),
        ] {
            anyhow::ensure!(v.is_finite(), "{name} must be finite, got {v}");
        }
        anyhow::ensure!(
            self.sparsity >= 0.0,
            "sparsity must not be negative, got {}",
            self.sparsity
        );
        anyhow::ensure!(
            self.checkpoint_min_seconds >= 0.0,
            "checkpoint_min_seconds must not be negative, got {}",
            self.checkpoint_min_seconds
        );
        self.lr_sigma.check("lr_sigma")?;
        self.lr_sh.check("lr_sh")?;
        Ok(())
    }

    /// The checks of a new run's schedule beyond [`PlenoxelsConfig::validate`] (which a checkpoint's
    /// configuration also passes, an import's among them: no steps, any grid): at least one
    /// step; every grid resolution in [`GRID_RES`]; upsampling at increasing steps before the
    /// last one, each to a finer grid.
    pub fn validate_schedule(&self) -> anyhow::Result<()> {
        anyhow::ensure!(self.iters >= 1, "iters must be at least 1");
        let (lo, hi) = (GRID_RES.start(), GRID_RES.end());
        anyhow::ensure!(
            GRID_RES.contains(&self.res),
            "res {}: grid resolutions must be in {lo} ..= {hi}",
            self.res
        );
        let mut prev = (None, self.res);
        for &(step, res) in &self.upsample {
            anyhow::ensure!(
                GRID_RES.contains(&res),
                "upsample [{step}, {res}]: grid resolutions must be in {lo} ..= {hi}"
            );
            anyhow::ensure!(
                step < self.iters,
                "upsample [{step}, {res}]: step {step} is past the last step ({} steps)",
                self.iters
            );
            anyhow::ensure!(
                prev.0.is_none_or(|p| step > p) && res > prev.1,
                "upsample [{step}, {res}]: each upsampling must come at a later step than the one \
                 before and to a finer grid (from {}³)",
                prev.1
            );
            prev = (Some(step), res);
        }
        Ok(())
    }

    /// The most memory the schedule's grids take while training: the starting grid's rows (a
    /// `share` of its vertices allocated: `grid::InitialFill::share`) and state, or an
    /// upsampled grid's dense links (its kept rows are checked when it is made); and the
    /// resolution that needs it.
    pub fn peak_grid_bytes(&self, share: f64) -> (f64, u32) {
        let start = self.res as f64;
        let rows = share * start * start * start;
        let first = (
            crate::grid::Grid::training_bytes([self.res; 3], rows as usize),
            self.res,
        );
        self.upsample
            .iter()
            .map(|&(_, r)| (crate::grid::Grid::training_bytes([r; 3], 0), r))
            .fold(first, |a, b| if b.0 > a.0 { b } else { a })
    }

    /// Rays per step for this schedule's final grid: `fast` sends its batch up to 128³ and,
    /// above, rays in proportion to the grid's resolution (8192 at 256³, 16384 at 512³): a
    /// finer grid's density converges only with more rays, and the thin and translucent parts
    /// of the development set's scenes are reconstructed better for it (docs/tuning.md);
    /// `paper` keeps its own.
    pub fn batch_for_grid(&self) -> u32 {
        let last = self.upsample.last().map_or(self.res, |u| u.1) as u64;
        match self.preset {
            Preset::Fast if last > FAST_BATCH_RES => {
                let scaled = self.batch as u64 * last / FAST_BATCH_RES;
                scaled.min(u32::MAX as u64) as u32
            }
            _ => self.batch,
        }
    }

    /// Resolution in force at step `t`.
    pub fn res_at(&self, t: u32) -> u32 {
        self.upsample
            .iter()
            .rfind(|(s, _)| *s <= t)
            .map_or(self.res, |(_, r)| *r)
    }
}

impl Scheduled for PlenoxelsConfig {
    fn schedule(&self) -> LoopSchedule {
        loop_schedule!(self)
    }
}

impl crate::checkpoint::Recorded for PlenoxelsConfig {
    fn validate(&self) -> anyhow::Result<()> {
        PlenoxelsConfig::validate(self)
    }

    fn iters_mut(&mut self) -> &mut u32 {
        &mut self.iters
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sparsity_must_be_finite_and_not_negative() {
        let mut c = PlenoxelsConfig::fast();
        c.sparsity = 1e-8;
        c.validate().unwrap();
        for (v, needle) in [
            (-1e-8, "sparsity must not be negative"),
            (f32::NAN, "sparsity must be finite"),
            (f32::INFINITY, "sparsity must be finite"),
        ] {
            c.sparsity = v;
            let e = c.validate().unwrap_err().to_string();
            assert!(e.contains(needle), "{v}: {e}");
        }
    }
}
