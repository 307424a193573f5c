//! Stage-2 (αSurf) configuration: the supplement's hyper-parameters per data category
//! (method.md §3.4–3.5) combined with a size preset — `paper` (50k steps of 5000 rays) or `fast`
//! (a CPU-sized schedule with every step-count scaled by the same factor). One trainer runs both.

use super::config::CHECKPOINT_MIN_SECONDS;
use super::preset::{Category, Preset};
use super::schedule::DelayedExp;
use super::steps::{loop_schedule, LoopSchedule, Scheduled};
use crate::grid::surface::SurfaceInit;
use crate::math::surface::{Truncation, TruncationCount};
use anyhow::{bail, ensure, Result};
use serde::{Deserialize, Serialize};

/// A linear ramp from `start` to `end` over the first `steps` steps, then `end`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Linear {
    pub start: f32,
    pub end: f32,
    pub steps: u32,
}

impl Linear {
    pub fn constant(v: f32) -> Self {
        Linear {
            start: v,
            end: v,
            steps: 0,
        }
    }

    /// The value at step `t`.
    pub fn at(&self, t: u32) -> f32 {
        if t >= self.steps {
            return self.end;
        }
        let u = t as f32 / self.steps as f32;
        self.start + u * (self.end - self.start)
    }
}

/// Everything that shapes a stage-2 run; stored in checkpoints and metrics.json.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SurfaceConfig {
    pub preset: Preset,
    pub category: Category,
    pub init: SurfaceInit,
    pub iters: u32,
    /// Rays per batch.
    pub batch: u32,
    /// The share of each batch drawn from the pixels the object covers (alpha above 0 in the
    /// training images, grown by `data::sampler::FOCUS_GROW` pixels), in [0, 1); the rest is
    /// uniform over every pixel, and each ray's loss is importance-weighted so that a batch's
    /// loss is the uniform batch's in expectation (`abi::rays::Focus`). 0: uniform, as the
    /// paper (views without alpha always are).
    #[serde(default)]
    pub ray_focus: f32,
    pub lr_delta: DelayedExp,
    pub lr_opacity: DelayedExp,
    pub lr_sh: DelayedExp,
    /// Truncation parameter a.
    pub a: Linear,
    /// How the truncation count runs along a ray: over every front hit (`ray`, the paper's
    /// rule), per structure (`structure`: it restarts where the ray enters the outermost level,
    /// so a surface seen through another keeps its hits), or per structure with one hit for each
    /// structure behind the first (`through`: a surface seen through another keeps its outermost
    /// level). Absent from checkpoints written before it: those counted per ray.
    #[serde(default)]
    pub truncation_count: TruncationCount,
    /// Entropy weight LH (per-ray term, mean over the batch).
    pub lambda_h: f32,
    /// Depth-consistency weight Lc, switched off from step `lambda_c_until` on.
    pub lambda_c: f32,
    pub lambda_c_until: u32,
    /// Lδ: TV on δ, a mean over a random chunk of this fraction of the vertex rows (1: every
    /// allocated vertex, as the paper).
    pub lambda_delta: f32,
    /// Absent from checkpoints written before it existed: those ran Lδ on every vertex.
    #[serde(default = "every_row")]
    pub delta_fraction: f32,
    /// TVα on a random chunk of this fraction of the slots.
    pub lambda_tv_alpha: f32,
    pub tv_alpha_fraction: f32,
    /// Lα on a random chunk of this fraction of the vertex rows.
    pub lambda_alpha: f32,
    pub alpha_fraction: f32,
    /// Ln1 (linear schedule) and Ln2 on a random chunk of this fraction of the cell slots.
    pub lambda_n1: Linear,
    pub lambda_n2: f32,
    pub normal_fraction: f32,
    /// Drop surfaces with α below this at the end.
    pub prune_alpha: f32,
    pub stop_thresh: f32,
    pub beta: f32,
    pub eps: f32,
    /// Write a checkpoint every this many steps (and at the end), once at least
    /// `checkpoint_min_seconds` have passed since the last one (as in stage 1's configuration).
    pub checkpoint_every: u32,
    #[serde(default)]
    pub checkpoint_min_seconds: f32,
    pub seed: u64,
}

fn every_row() -> f32 {
    1.0
}

/// The `fast` preset's initial opacity scale (σα = s·σ) on a 128³ grid. Thin parts start nearly
/// opaque (the supplement's 0.05), so that the photometric loss selects among levels that all
/// render, rather than waiting for σα to rise; semi-transparent layers start lower (0.01); the
/// other categories keep the released code's 0.005. Chosen on the development set
/// (docs/tuning.md).
pub fn fast_alpha_init_scale(category: Category) -> f32 {
    match category {
        Category::Thin => 0.05,
        Category::Translucent => 0.01,
        _ => SurfaceInit::default().alpha_init_scale,
    }
}

impl SurfaceConfig {
    /// Truncated compositing at step `step`.
    pub fn truncation(&self, step: u32) -> Truncation {
        Truncation {
            a: self.a.at(step),
            count: self.truncation_count,
        }
    }

    /// The paper's set-up for `category` (50k steps × 5000 rays).
    pub fn paper(category: Category) -> Self {
        // Synthetic / thin values (supplement B.2), then the per-category changes.
        let mut c = SurfaceConfig {
            preset: Preset::Paper,
            category,
            init: SurfaceInit::default(),
            iters: 50_000,
            batch: 5000,
            ray_focus: 0.0,
            lr_delta: DelayedExp {
                init: 1e-5,
                last: 1e-5,
                max_steps: 50_000,
                delay_steps: 25_000,
                delay_mult: 0.01,
            },
            lr_opacity: DelayedExp {
                init: 1e-2,
                last: 1e-3,
                max_steps: 50_000,
                delay_steps: 25_000,
                delay_mult: 0.01,
            },
            lr_sh: DelayedExp::constant(1e-3),
            a: Linear {
                start: 5.0,
                end: 2.0,
                steps: 10_000,
            },
            truncation_count: TruncationCount::Ray,
            lambda_h: 1e-4,
            lambda_c: 1e-6,
            lambda_c_until: 10_000,
            lambda_delta: 1e-3,
            delta_fraction: 1.0,
            lambda_tv_alpha: 1e-5,
            tv_alpha_fraction: 0.01,
            lambda_alpha: 1e-9,
            alpha_fraction: 0.1,
            lambda_n1: Linear::constant(1e-6),
            lambda_n2: 0.0,
            normal_fraction: 1.0,
            prune_alpha: 0.1,
            stop_thresh: 1e-4,
            beta: 0.95,
            eps: 1e-8,
            checkpoint_every: 5000,
            checkpoint_min_seconds: CHECKPOINT_MIN_SECONDS,
            seed: 0,
        };
        match category {
            Category::Thin | Category::Synthetic => {}
            Category::Translucent => {
                // Surfaces behind semi-transparent ones: each structure behind the first the
                // ray enters keeps its outermost level (docs/tuning.md).
                c.truncation_count = TruncationCount::Through;
                c.lambda_delta = 1e-5;
                c.lambda_alpha = 1e-11;
                c.lambda_n1 = Linear {
                    start: 1e-2,
                    end: 1e-4,
                    steps: c.iters,
                };
                c.lambda_n2 = 1e-4;
            }
            Category::Real => {
                c.init.density_levels = vec![10.0, 30.0, 50.0];
                c.lr_delta.init = 1e-4;
                c.lr_delta.last = 1e-4;
                c.lambda_delta = 5e-3;
                c.lambda_n1 = Linear {
                    start: 1e-2,
                    end: 1e-3,
                    steps: c.iters,
                };
                c.lambda_n2 = 1e-3;
            }
            // The synthetic set-up (levels 10…90, Ln1 1e-6, no Ln2) with DTU's own changes
            // (method.md §3.4).
            Category::Dtu => {
                c.lambda_delta = 0.05;
                c.lambda_h = 1e-3;
                c.lambda_alpha = 1e-8;
                c.lr_delta.init = 1e-4;
                c.lr_delta.last = 1e-6;
                c.a = Linear::constant(5.0);
            }
        }
        c
    }

    /// Reject values no run can use (after `--set` overrides): negative or non-finite rates,
    /// weights and fractions, fractions above 1, no levels.
    pub fn validate(&self) -> Result<()> {
        for (name, lr) in [
            ("lr_delta", &self.lr_delta),
            ("lr_opacity", &self.lr_opacity),
            ("lr_sh", &self.lr_sh),
        ] {
            lr.check(name)?;
        }
        let weights = [
            ("lambda_h", self.lambda_h),
            ("lambda_c", self.lambda_c),
            ("lambda_delta", self.lambda_delta),
            ("lambda_tv_alpha", self.lambda_tv_alpha),
            ("lambda_alpha", self.lambda_alpha),
            ("lambda_n1.start", self.lambda_n1.start),
            ("lambda_n1.end", self.lambda_n1.end),
            ("lambda_n2", self.lambda_n2),
            ("prune_alpha", self.prune_alpha),
            ("stop_thresh", self.stop_thresh),
            ("eps", self.eps),
            ("a.start", self.a.start),
            ("a.end", self.a.end),
        ];
        for (name, v) in weights {
            ensure!(
                v.is_finite() && v >= 0.0,
                "{name} must be finite and ≥ 0, got {v}"
            );
        }
        ensure!(
            (0.0..1.0).contains(&self.ray_focus),
            "ray_focus must be in [0, 1), got {}",
            self.ray_focus
        );
        for (name, v) in [
            ("delta_fraction", self.delta_fraction),
            ("tv_alpha_fraction", self.tv_alpha_fraction),
            ("alpha_fraction", self.alpha_fraction),
            ("normal_fraction", self.normal_fraction),
            ("beta", self.beta),
        ] {
            ensure!(
                (0.0..=1.0).contains(&v),
                "{name} must be in [0, 1], got {v}"
            );
        }
        ensure!(
            !self.init.density_levels.is_empty()
                && self.init.density_levels.iter().all(|l| l.is_finite()),
            "init.density_levels must be a non-empty list of finite numbers"
        );
        ensure!(
            self.iters > 0 && self.batch > 0 && self.checkpoint_every > 0,
            "iters, batch and checkpoint_every must be at least 1"
        );
        ensure!(
            self.checkpoint_min_seconds >= 0.0 && self.checkpoint_min_seconds.is_finite(),
            "checkpoint_min_seconds must be a finite number of seconds ≥ 0, got {}",
            self.checkpoint_min_seconds
        );
        Ok(())
    }

    /// `preset` (paper or fast) for `category`.
    pub fn preset(preset: Preset, category: Category) -> Result<Self> {
        let paper = Self::paper(category);
        match preset {
            Preset::Paper => Ok(paper),
            Preset::Fast => {
                let mut c = paper.scaled(1500);
                c.preset = Preset::Fast;
                c.batch = 4096;
                c.checkpoint_every = 500;
                // Lα fades the surfaces no ray sees (inner level sets of solids). With 33× fewer
                // steps than the paper it needs a larger weight to act on the synthetic and
                // translucent set-ups; thin keeps the paper's weight, since its higher σα start
                // (`fast_alpha_init_scale`) would otherwise fade the thin parts rays rarely hit.
                c.lambda_alpha *= match category {
                    Category::Thin => 1.0,
                    Category::Translucent => 1e4,
                    _ => 1e3,
                };
                // Semi-transparent layers: Lc on for the whole run, at a weight that competes
                // with the photometric term (the paper's 1e-6 for its first fifth does nothing in
                // 1500 steps), pulls a layer's level crossings toward the depth of its strongest.
                if category == Category::Translucent {
                    c.lambda_c = 10.0;
                    c.lambda_c_until = c.iters;
                }
                // Thin parts start nearly opaque (`fast_alpha_init_scale`); σα at the paper's
                // rate then fades the surfaces that few rays reach (a sound box's sides) below
                // the extraction's α within 1500 steps, so thin trains it at about a third of
                // the rate.
                if category == Category::Thin {
                    c.lr_opacity.init = 3e-3;
                    c.lr_opacity.last = 3e-4;
                }
                // Colour must re-fit from volume to surface rendering in 1500 steps.
                c.lr_sh = DelayedExp::constant(1e-2);
                // 1500 steps of uniform batches shade the object's pixels (a tenth of a view's,
                // or less) less than once each: three quarters of each batch are drawn from the
                // pixels the object covers, importance-weighted so that the loss is the uniform
                // batch's in expectation.
                c.ray_focus = 0.75;
                c.init.alpha_init_scale = fast_alpha_init_scale(category);
                // RMSProp leaves a vertex's σα alone in steps that give it no gradient, so its
                // state does not decay between Lα visits: a larger chunk keeps the fading rate.
                c.alpha_fraction = 0.3;
                // Ln1/Ln2 on a random 10 % of the cells each step (a mean over the chunk: the same
                // loss in expectation, at a tenth of the cost). Lδ stays on every vertex: δ is
                // updated only where it has a gradient, and a chunk would leave most rows still.
                c.normal_fraction = 0.1;
                Ok(c)
            }
            Preset::Imported => bail!("preset `imported` has no stage-2 schedule"),
        }
    }

    /// Fit the preset to the stage-1 grid it starts from (`n`³ vertices); the `paper` preset is
    /// left as it is (its 50k steps adapt by themselves).
    ///
    /// The `fast` preset's initial opacity scale is at least 0.005·(n/128)^1.5: its 1500 steps
    /// shade each surface vertex about (128/n)² times as often as at 128³, too rarely for σα to
    /// rise from a small start before truncation leaves each ray two hits, and the outer levels
    /// then let the background through. Every learning rate keeps the paper's value at every
    /// grid (figures: docs/tuning.md).
    pub fn fit_grid(&mut self, n: u32) {
        if self.preset != Preset::Fast {
            return;
        }
        let f = (n as f32 / 128.0).max(1.0);
        let grid_floor = SurfaceInit::default().alpha_init_scale * f * f.sqrt();
        self.init.alpha_init_scale = fast_alpha_init_scale(self.category).max(grid_floor);
    }

    /// The same schedule over `iters` steps: every step count (delays, decays, a's ramp, the
    /// Lc cut-off, Ln1's ramp) scales by iters / self.iters.
    pub fn scaled(&self, iters: u32) -> Self {
        let f = |s: u32| ((s as u64 * iters as u64) / self.iters.max(1) as u64) as u32;
        let mut c = self.clone();
        for lr in [&mut c.lr_delta, &mut c.lr_opacity, &mut c.lr_sh] {
            lr.max_steps = f(lr.max_steps).max(1);
            lr.delay_steps = f(lr.delay_steps);
        }
        c.a.steps = f(c.a.steps);
        c.lambda_c_until = f(c.lambda_c_until);
        c.lambda_n1.steps = f(c.lambda_n1.steps);
        c.checkpoint_every = c.checkpoint_every.min(iters).max(1);
        c.iters = iters;
        c
    }
}

impl Scheduled for SurfaceConfig {
    fn schedule(&self) -> LoopSchedule {
        loop_schedule!(self)
    }
}

impl crate::checkpoint::Recorded for SurfaceConfig {
    fn validate(&self) -> Result<()> {
        SurfaceConfig::validate(self)
    }

    fn iters_mut(&mut self) -> &mut u32 {
        &mut self.iters
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn categories_and_scaling() {
        let thin = SurfaceConfig::paper(Category::Thin);
        assert_eq!(thin.a.at(0), 5.0);
        assert_eq!(thin.a.at(5000), 3.5);
        assert_eq!(thin.a.at(20_000), 2.0);
        let tr = SurfaceConfig::paper(Category::Translucent);
        assert_eq!(tr.lambda_n1.at(0), 1e-2);
        assert!((tr.lambda_n1.at(50_000) - 1e-4).abs() < 1e-9);
        // DTU: the synthetic set-up (five levels, Ln1 1e-6, no Ln2) with its own changes.
        let dtu = SurfaceConfig::paper(Category::Dtu);
        assert_eq!(dtu.a.at(30_000), 5.0);
        assert_eq!(dtu.init.density_levels, thin.init.density_levels);
        assert_eq!((dtu.lambda_n1, dtu.lambda_n2), (thin.lambda_n1, 0.0));
        assert_eq!(
            (dtu.lambda_delta, dtu.lambda_h, dtu.lambda_alpha),
            (0.05, 1e-3, 1e-8)
        );
        assert_eq!((dtu.lr_delta.init, dtu.lr_delta.last), (1e-4, 1e-6));
        let real = SurfaceConfig::paper(Category::Real);
        assert_eq!(real.init.density_levels, vec![10.0, 30.0, 50.0]);
        let fast = SurfaceConfig::preset(Preset::Fast, Category::Thin).unwrap();
        assert_eq!(fast.iters, 1500);
        assert_eq!(fast.a.steps, 300);
        assert_eq!(fast.lr_opacity.delay_steps, 750);
        assert_eq!(fast.lambda_c_until, 300);
        // σα: thin at about a third of the paper's rate, the other set-ups at the paper's.
        assert_eq!((fast.lr_opacity.init, fast.lr_opacity.last), (3e-3, 3e-4));
        // Lα: the paper's weight for thin, larger for the other set-ups' short schedule.
        assert_eq!(fast.lambda_alpha, thin.lambda_alpha);
        let fast_syn = SurfaceConfig::preset(Preset::Fast, Category::Synthetic).unwrap();
        assert!((fast_syn.lambda_alpha - 1e-6).abs() < 1e-12);
        let fast_tr = SurfaceConfig::preset(Preset::Fast, Category::Translucent).unwrap();
        assert!((fast_tr.lambda_alpha - 1e-7).abs() < 1e-14);
        assert_eq!(
            (fast_tr.lr_opacity.init, fast_tr.lr_opacity.last),
            (1e-2, 1e-3)
        );
        // Lc: translucent all run at 10, the others the paper's for the first fifth.
        assert_eq!((fast_tr.lambda_c, fast_tr.lambda_c_until), (10.0, 1500));
        assert_eq!(fast.lambda_c, thin.lambda_c);
        for c in [&fast, &fast_syn, &fast_tr] {
            assert_eq!(c.lr_sh.at(0), 1e-2);
            assert_eq!(c.lr_sh.at(1400), 1e-2);
        }
        assert_eq!(thin.lr_sh.at(0), 1e-3);
        assert_eq!((fast.normal_fraction, fast.delta_fraction), (0.1, 1.0));
        assert_eq!((thin.normal_fraction, thin.delta_fraction), (1.0, 1.0));
        // A configuration saved before delta_fraction existed reads as Lδ on every vertex.
        let mut old = serde_json::to_value(&fast).unwrap();
        old.as_object_mut().unwrap().remove("delta_fraction");
        let read: SurfaceConfig = serde_json::from_value(old).unwrap();
        assert_eq!(read, fast);
    }

    #[test]
    fn only_the_fast_preset_focuses_its_batches() {
        for cat in [Category::Thin, Category::Translucent, Category::Real] {
            assert_eq!(SurfaceConfig::paper(cat).ray_focus, 0.0);
            let fast = SurfaceConfig::preset(Preset::Fast, cat).unwrap();
            assert_eq!(fast.ray_focus, 0.75);
            fast.validate().unwrap();
            for bad in [1.0, -0.1, f32::NAN] {
                let c = SurfaceConfig {
                    ray_focus: bad,
                    ..fast.clone()
                };
                let e = c.validate().unwrap_err().to_string();
                assert!(e.contains("ray_focus"), "{e}");
            }
        }
    }

    #[test]
    fn fast_opacity_init_per_category_and_grid() {
        let at = |preset: Preset, category: Category, n: u32| {
            let mut c = SurfaceConfig::preset(preset, category).unwrap();
            c.fit_grid(n);
            c.init.alpha_init_scale
        };
        let close = |a: f32, b: f32| (a - b).abs() <= 1e-6 * b;
        let floor = |n: f32| 0.005 * (n / 128.0).powf(1.5);
        for n in [32u32, 64, 128, 256, 512, 1024] {
            let g = floor(n as f32).max(0.005);
            // Each category's start, raised to the grid's floor above 128³.
            assert!(
                close(at(Preset::Fast, Category::Thin, n), g.max(0.05)),
                "{n}"
            );
            assert!(
                close(at(Preset::Fast, Category::Translucent, n), g.max(0.01)),
                "{n}"
            );
            assert!(close(at(Preset::Fast, Category::Synthetic, n), g), "{n}");
            // The paper preset keeps the released code's value at every size.
            assert!(close(at(Preset::Paper, Category::Thin, n), 0.005), "{n}");
        }
        assert!(close(at(Preset::Fast, Category::Translucent, 512), 0.04));
        assert!(close(at(Preset::Fast, Category::Thin, 1024), floor(1024.0)));
    }

    #[test]
    fn fast_delta_rate_is_the_papers_at_every_grid() {
        for category in [Category::Thin, Category::Translucent, Category::Synthetic] {
            for n in [64, 128, 256, 512, 1024] {
                let mut c = SurfaceConfig::preset(Preset::Fast, category).unwrap();
                c.fit_grid(n);
                assert_eq!(
                    c.lr_delta,
                    SurfaceConfig::paper(category).scaled(1500).lr_delta
                );
                assert_eq!(
                    (c.lr_delta.init, c.lr_delta.last),
                    (1e-5, 1e-5),
                    "{category} {n}"
                );
            }
        }
    }
}
