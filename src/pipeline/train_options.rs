//! The options of `train` ([`TrainOptions`], also its command-line flags): which stage, the
//! dataset, the run directory, the preset and its overrides; the checks that refuse flags a stage
//! would ignore; and each stage's configuration built from them.

use crate::backend::Backend;
use crate::data::ndc::Space;
use crate::data::BackgroundMode;
use crate::run::Open;
use crate::train::config::GRID_RES;
use crate::train::{Category, PlenoxelsConfig, Preset, SurfaceConfig};
use anyhow::{bail, ensure, Context, Result};
use serde::{de::DeserializeOwned, Serialize};
use std::path::PathBuf;

/// Which stage to train.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// Stage 1: Plenoxels density + SH grid (writes plenoxels.npz).
    Plenoxels,
    /// Stage 2: αSurf surfaces initialised from a stage-1 grid (`--init`; writes surface.npz).
    Surface,
    /// Stage 1 into OUT/plenoxels, then stage 2 from it into OUT/surface.
    All,
}

/// Options of `train` (its command-line flags).
#[derive(clap::Args, Debug, Clone)]
pub struct TrainOptions {
    /// Which stage.
    #[arg(long, value_enum, default_value = "plenoxels")]
    pub stage: Stage,
    /// Dataset directory (NeRF-synthetic format, e.g. from `make-scene`).
    #[arg(long)]
    pub data: PathBuf,
    /// Stage 2: the stage-1 run directory (its plenoxels.npz) or an svox2 `ckpt.npz` to
    /// initialise from (required unless resuming).
    #[arg(long)]
    pub init: Option<PathBuf>,
    /// Stage 2: the data category whose hyper-parameters from the paper's supplement apply
    /// (levels, learning rates, regulariser weights, truncation schedule).
    /// [default: thin]
    #[arg(long, value_enum)]
    pub category: Option<Category>,
    /// Stage 2: initial raw opacity σα = s·σ, s > 0. Default: preset `paper` 0.005 (the released
    /// code); preset `fast` 0.05 for thin, 0.01 for translucent, 0.005 otherwise, and at least
    /// 0.005·(N/128)^1.5 on a stage-1 grid of N³: its short schedule cannot raise σα far enough
    /// on a fine grid before truncation leaves each ray two hits.
    #[arg(long)]
    pub alpha_init_scale: Option<f32>,
    /// Stage 2 steps (overrides the preset; with `--stage all`, `--iters` is stage 1's).
    #[arg(long)]
    pub surface_iters: Option<u32>,
    /// Stage 2: override any field of the configuration (as printed in metrics.json), e.g.
    /// `--set lambda_h=1e-3 --set lr_delta.init=1e-4`; the value is JSON. Repeatable.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Stage 1: override any field of its configuration (as printed in its metrics.json), e.g.
    /// `--plenoxels-set tv_sigma=1e-6 --plenoxels-set lr_sigma.last=1.0`; the value is JSON,
    /// applied after `--res`, `--iters` and `--batch`. Repeatable.
    #[arg(long = "plenoxels-set", value_name = "KEY=VALUE")]
    pub plenoxels_set: Vec<String>,
    /// Run directory: checkpoints, test renders, metrics.json.
    #[arg(long)]
    pub out: PathBuf,
    /// The schedule of both stages [default: fast].
    #[arg(long, value_enum)]
    pub preset: Option<Preset>,
    /// Where the kernels run.
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    pub backend: Backend,
    /// Number of steps (overrides the preset; stage 1's learning-rate decays keep their length,
    /// stage 2's schedules scale with it).
    #[arg(long)]
    pub iters: Option<u32>,
    /// Final grid resolution (the preset's upsampling schedule is scaled to it).
    #[arg(long)]
    pub res: Option<u32>,
    /// Rays per batch, both stages (overrides the presets: `fast` 4096, stage 1 above a 128³ grid
    /// 4096 × N/128, e.g. 8192 at 256³, 16384 at 512³; `paper` 5000).
    #[arg(long)]
    pub batch: Option<u32>,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Box-downscale the images by this factor.
    #[arg(long, default_value_t = 1)]
    pub downscale: u32,
    /// The scene box in dataset (world) units, `xmin,ymin,zmin,xmax,ymax,zmax`: the grid is the
    /// cube around it (centred, as wide as its widest side). Default: the dataset's (for a
    /// capture without masks, the foreground box found from the cameras; `inspect` prints it).
    /// Recorded in run.json; `--resume` and stage 2 from a stage-1 run directory take the
    /// recorded one.
    #[arg(
        long = "box",
        value_name = "XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    pub scene_box: Option<Vec<f32>>,
    /// Where the grid lies. `auto`: NDC for a forward-facing capture (every camera looking
    /// within 45° of their mean direction) whose nearest depth is known (sparse points in view,
    /// LLFF's near bounds), else the box; `box`: the dataset's box (or `--box`); `ndc`: the
    /// NDC cube of the mean camera, from the near plane (0.75 × the nearest depth) to infinite
    /// depth, as the paper and svox2 train forward-facing captures. `inspect` says what `auto`
    /// picks and why; run.json records it; `extract` writes points back in dataset units.
    #[arg(long, value_enum, default_value_t = Space::Auto)]
    pub space: Space,
    /// What lies behind the scene: images with alpha or masks are composited on it at load,
    /// and every render and training pass composites on it. `auto`: white for images with
    /// alpha and for forward-facing captures in NDC, `spheres` for a 360° capture without
    /// alpha (resuming or from `--init RUN`: that run's); `learned`: a constant colour trained
    /// with the scene; `spheres`: learned spheres around the grid box in front of a learned
    /// colour, for views that see a room (stage 1 trains them, stage 2 keeps them). The
    /// learned ones refuse images with alpha.
    #[arg(long, value_enum, default_value_t = BackgroundMode::Auto)]
    pub background: BackgroundMode,
    /// Write a checkpoint exactly every N steps. Default: the preset's (`fast` 500 steps, `paper`
    /// 5000), at the first such step a minute or more after the last checkpoint.
    #[arg(long)]
    pub checkpoint_every: Option<u32>,
    /// Continue from the run directory's checkpoint (its configuration wins).
    #[arg(long, conflicts_with = "overwrite")]
    pub resume: bool,
    /// Replace the run already in `--out` (only a run: a folder that is not one is never
    /// overwritten).
    #[arg(long)]
    pub overwrite: bool,
    /// With `--resume` or `--init RUN`: use `--data` even though it is not the dataset that run
    /// was trained on (another content fingerprint or scene normalisation, or, for runs from
    /// before fingerprints were recorded, another folder), which is refused without it.
    #[arg(long)]
    pub allow_other_data: bool,
    /// Hide the progress bar.
    #[arg(long)]
    pub quiet: bool,
}

impl TrainOptions {
    /// The preset asked for, or the default `fast`. `None` in the field means "not given", so
    /// `--resume` can tell an explicit `--preset fast` on a `paper` run from no flag at all.
    pub fn preset(&self) -> Preset {
        self.preset.unwrap_or(Preset::Fast)
    }

    /// The stage-2 category asked for, or the default `thin` (`None`: not given).
    pub fn category(&self) -> Category {
        self.category.unwrap_or(Category::Thin)
    }

    /// The defaults of every flag, training `stage` on `data` into `out`.
    pub fn new(stage: Stage, data: PathBuf, out: PathBuf) -> TrainOptions {
        TrainOptions {
            stage,
            data,
            init: None,
            category: None,
            alpha_init_scale: None,
            surface_iters: None,
            set: Vec::new(),
            plenoxels_set: Vec::new(),
            out,
            preset: None,
            backend: Backend::Auto,
            iters: None,
            res: None,
            batch: None,
            seed: 0,
            downscale: 1,
            scene_box: None,
            space: Space::Auto,
            background: BackgroundMode::Auto,
            checkpoint_every: None,
            resume: false,
            overwrite: false,
            allow_other_data: false,
            quiet: false,
        }
    }

    /// The stage-1 configuration: the preset, then the overrides.
    pub fn plenoxels_config(&self) -> Result<PlenoxelsConfig> {
        let mut cfg = PlenoxelsConfig::preset(self.preset())?;
        cfg.seed = self.seed;
        if let Some(n) = self.iters {
            if n == 0 {
                bail!("--iters must be at least 1");
            }
            cfg.upsample
                .iter_mut()
                .for_each(|u| u.0 = (u.0 as u64 * n as u64 / cfg.iters as u64) as u32);
            cfg.checkpoint_every = cfg.checkpoint_every.min(n);
            cfg.iters = n;
        }
        if let Some(r) = self.res {
            if !GRID_RES.contains(&r) {
                bail!(
                    "--res {r}: expected {} ..= {}",
                    GRID_RES.start(),
                    GRID_RES.end()
                );
            }
            let last = cfg.upsample.last().map_or(cfg.res, |u| u.1);
            cfg.res = (cfg.res as u64 * r as u64 / last as u64).max(8) as u32;
            cfg.upsample
                .iter_mut()
                .for_each(|u| u.1 = (u.1 as u64 * r as u64 / last as u64) as u32);
        }
        cfg.batch = cfg.batch_for_grid();
        if let Some(c) = self.checkpoint_every {
            if c == 0 {
                bail!("--checkpoint-every must be at least 1");
            }
            cfg.checkpoint_every = c;
            cfg.checkpoint_min_seconds = 0.0;
        }
        if let Some(b) = self.batch {
            if b == 0 {
                bail!("--batch must be at least 1");
            }
            cfg.batch = b;
        }
        for kv in &self.plenoxels_set {
            cfg = set_field(&cfg, kv, "--plenoxels-set")?;
        }
        // The same checks whichever flag set a value.
        cfg.validate()
            .and_then(|()| cfg.validate_schedule())
            .with_context(|| settings_named("stage-1", "--plenoxels-set", &self.plenoxels_set))?;
        Ok(cfg)
    }

    /// Refuse a new stage-1 run whose grids (the first with a `share` of its vertices
    /// allocated) or batch cannot fit in the memory this process may use, naming the flag that
    /// sized them.
    pub fn check_plenoxels_memory(&self, cfg: &PlenoxelsConfig, share: f64) -> Result<()> {
        let (grid_bytes, grid_res) = cfg.peak_grid_bytes(share);
        let res_flag = self.res.map(|r| format!("--res {r}"));
        crate::run::memory::ensure_fits(
            &format!(
                "a {grid_res}³ training grid ({})",
                self.source(
                    ("--plenoxels-set", &self.plenoxels_set),
                    &["res", "upsample"],
                    res_flag
                )
            ),
            grid_bytes,
        )?;
        let batch_flag = self.batch.map(|b| format!("--batch {b}"));
        check_batch_memory(
            cfg.batch,
            &self.source(
                ("--plenoxels-set", &self.plenoxels_set),
                &["batch"],
                batch_flag,
            ),
        )
    }

    /// Where a configuration value came from, for messages: the last `FLAG KEY=VALUE` of `sets`
    /// whose key is one of `keys` (or a field inside one), else the flag, else the preset.
    fn source(
        &self,
        (set_flag, sets): (&str, &[String]),
        keys: &[&str],
        flag: Option<String>,
    ) -> String {
        sets.iter()
            .rfind(|kv| {
                let key = kv.split_once('=').map_or(kv.as_str(), |(k, _)| k);
                let head = key.split('.').next().unwrap_or(key);
                keys.contains(&head)
            })
            .map(|kv| format!("{set_flag} {kv}"))
            .or(flag)
            .unwrap_or_else(|| format!("preset {}", self.preset()))
    }

    /// How these options open their run directory.
    pub fn open_mode(&self) -> Open {
        match (self.resume, self.overwrite) {
            (true, _) => Open::Resume,
            (false, true) => Open::Overwrite,
            (false, false) => Open::Fresh,
        }
    }

    /// Refuse flags the stage asked for would ignore.
    pub fn check_stage_flags(&self) -> Result<()> {
        let mut ignored = Vec::new();
        if self.stage == Stage::Plenoxels {
            let stage2_only = [
                ("--init", self.init.is_some()),
                ("--category", self.category.is_some()),
                ("--set", !self.set.is_empty()),
                ("--alpha-init-scale", self.alpha_init_scale.is_some()),
                ("--surface-iters", self.surface_iters.is_some()),
            ];
            ignored.extend(stage2_only.iter().filter(|f| f.1).map(|f| f.0));
        }
        if self.stage == Stage::Surface {
            let stage1_only = [
                ("--res", self.res.is_some()),
                ("--plenoxels-set", !self.plenoxels_set.is_empty()),
            ];
            ignored.extend(stage1_only.iter().filter(|f| f.1).map(|f| f.0));
        }
        if self.stage == Stage::All && self.init.is_some() {
            ignored.push("--init");
        }
        if self.stage == Stage::Surface && self.iters.is_some() && self.surface_iters.is_some() {
            bail!(
                "--iters and --surface-iters both give stage 2's steps with --stage surface (one \
                 would be ignored); give one of them"
            );
        }
        // Only a run trained before (the one resumed, or stage 2's --init) has a dataset to
        // compare with.
        let compared = self.resume || (self.stage == Stage::Surface && self.init.is_some());
        if self.allow_other_data && !compared {
            bail!(
                "--allow-other-data applies with --resume or --stage surface --init RUN (a run \
                 trained before); leave it out"
            );
        }
        if !ignored.is_empty() {
            bail!(
                "{} {} not used by --stage {} ({}); leave {} out",
                ignored.join(", "),
                if ignored.len() == 1 { "is" } else { "are" },
                match self.stage {
                    Stage::Plenoxels => "plenoxels",
                    Stage::Surface => "surface",
                    Stage::All => "all",
                },
                match self.stage {
                    Stage::Plenoxels => "they configure stage 2",
                    Stage::Surface => "stage 1 is --init's",
                    Stage::All => "stage 2 starts from this run's own stage 1",
                },
                if ignored.len() == 1 { "it" } else { "them" }
            );
        }
        for (name, v) in [
            ("--iters", self.iters),
            ("--surface-iters", self.surface_iters),
        ] {
            if v == Some(0) {
                bail!("{name} must be at least 1");
            }
        }
        Ok(())
    }

    /// The stage-2 configuration for a stage-1 grid of `grid_n`³ vertices: the preset fitted to the
    /// grid, then the command line's overrides.
    pub fn surface_config(&self, grid_n: u32) -> Result<SurfaceConfig> {
        let mut cfg = SurfaceConfig::preset(self.preset(), self.category())?;
        cfg.fit_grid(grid_n);
        cfg.seed = self.seed;
        if let Some(n) = self.surface_iters.or(self.iters) {
            ensure!(n > 0, "the number of stage-2 steps must be at least 1");
            let preset = cfg.preset;
            cfg = cfg.scaled(n);
            cfg.preset = preset;
        }
        if let Some(b) = self.batch {
            ensure!(b > 0, "--batch must be at least 1");
            cfg.batch = b;
        }
        if let Some(c) = self.checkpoint_every {
            ensure!(c > 0, "--checkpoint-every must be at least 1");
            cfg.checkpoint_every = c;
            cfg.checkpoint_min_seconds = 0.0;
        }
        for kv in &self.set {
            cfg = set_field(&cfg, kv, "--set")?;
        }
        if let Some(s) = self.alpha_init_scale {
            ensure!(
                s > 0.0 && s.is_finite(),
                "--alpha-init-scale must be positive, got {s}"
            );
            cfg.init.alpha_init_scale = s;
        }
        cfg.validate()
            .with_context(|| settings_named("stage-2", "--set", &self.set))?;
        Ok(cfg)
    }

    /// Refuse a new stage-2 run whose batch cannot fit in the memory this process may use.
    pub fn check_surface_memory(&self, cfg: &SurfaceConfig) -> Result<()> {
        let batch_flag = self.batch.map(|b| format!("--batch {b}"));
        check_batch_memory(
            cfg.batch,
            &self.source(("--set", &self.set), &["batch"], batch_flag),
        )
    }
}

/// Bytes a training step holds per ray of its batch: the sampled batch, its flat copies handed
/// to the backend and the backend's per-ray buffers. Peak RSS grows by about 100 B per ray on the
/// CPU backend (stage 1, `--batch` 2000 against 400000); the Vulkan backend also stages its
/// copies, hence the margin.
const BYTES_PER_BATCH_RAY: f64 = 256.0;

/// Refuse a batch whose per-step buffers cannot fit in the memory available; `source` names
/// the flag that set it.
fn check_batch_memory(batch: u32, source: &str) -> Result<()> {
    crate::run::memory::ensure_fits(
        &format!("a batch of {batch} rays ({source})"),
        batch as f64 * BYTES_PER_BATCH_RAY,
    )
}

/// The context of a configuration check: which stage, and the `FLAG KEY=VALUE` settings applied
/// (a value they set is refused as the flag's own would be).
fn settings_named(stage: &str, flag: &str, sets: &[String]) -> String {
    if sets.is_empty() {
        format!("the {stage} configuration")
    } else {
        let named: Vec<String> = sets.iter().map(|kv| format!("{flag} {kv}")).collect();
        format!("the {stage} configuration with {}", named.join(" "))
    }
}

/// `FLAG key.path=json` (`--set`, `--plenoxels-set`): patch one field of a configuration.
fn set_field<T: Serialize + DeserializeOwned>(cfg: &T, kv: &str, flag: &str) -> Result<T> {
    let (key, value) = kv
        .split_once('=')
        .with_context(|| format!("{flag} {kv}: expected KEY=VALUE"))?;
    let value: serde_json::Value = serde_json::from_str(value)
        .or_else(|_| serde_json::from_str(&format!("\"{value}\"")))
        .with_context(|| format!("{flag} {kv}: the value is not JSON"))?;
    let mut v = serde_json::to_value(cfg)?;
    let mut slot = &mut v;
    for part in key.split('.') {
        slot = slot
            .get_mut(part)
            .with_context(|| format!("{flag} {kv}: no configuration field {key:?}"))?;
    }
    ensure!(
        std::mem::discriminant(slot) == std::mem::discriminant(&value)
            || (slot.is_number() && value.is_number()),
        "{flag} {kv}: {key} is {slot}, not {value}"
    );
    *slot = value;
    serde_json::from_value(v).with_context(|| format!("{flag} {kv}: invalid value for {key}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn batch(preset: Preset, res: Option<u32>, batch: Option<u32>) -> u32 {
        let opts = TrainOptions {
            preset: Some(preset),
            res,
            batch,
            ..TrainOptions::new(Stage::Plenoxels, "d".into(), "o".into())
        };
        opts.plenoxels_config().unwrap().batch
    }

    #[test]
    fn fast_sends_more_rays_to_grids_above_128() {
        assert_eq!(batch(Preset::Fast, None, None), 4096);
        assert_eq!(batch(Preset::Fast, Some(64), None), 4096);
        assert_eq!(batch(Preset::Fast, Some(256), None), 8192);
        assert_eq!(batch(Preset::Fast, Some(384), None), 12288);
        assert_eq!(batch(Preset::Fast, Some(512), None), 16384);
        assert_eq!(batch(Preset::Fast, Some(512), Some(1000)), 1000);
        assert_eq!(batch(Preset::Paper, None, None), 5000);
        assert_eq!(batch(Preset::Paper, Some(1024), None), 5000);
    }

    #[test]
    fn an_explicit_checkpoint_interval_is_kept_exactly() {
        let opts = |every: Option<u32>| TrainOptions {
            checkpoint_every: every,
            ..TrainOptions::new(Stage::All, "d".into(), "o".into())
        };
        let stage2 = |o: &TrainOptions| o.surface_config(128).unwrap();
        let preset = opts(None);
        let (s1, s2) = (preset.plenoxels_config().unwrap(), stage2(&preset));
        assert_eq!(
            (s1.checkpoint_every, s1.checkpoint_min_seconds),
            (500, 60.0)
        );
        assert_eq!(
            (s2.checkpoint_every, s2.checkpoint_min_seconds),
            (500, 60.0)
        );
        let given = opts(Some(7));
        let (s1, s2) = (given.plenoxels_config().unwrap(), stage2(&given));
        assert_eq!((s1.checkpoint_every, s1.checkpoint_min_seconds), (7, 0.0));
        assert_eq!((s2.checkpoint_every, s2.checkpoint_min_seconds), (7, 0.0));
    }

    #[test]
    fn plenoxels_set_patches_stage_one_and_names_its_flag() {
        let opts = |set: &[&str]| TrainOptions {
            batch: Some(1000),
            plenoxels_set: set.iter().map(|s| s.to_string()).collect(),
            ..TrainOptions::new(Stage::Plenoxels, "d".into(), "o".into())
        };
        let cfg = opts(&["tv_sigma=1e-6", "lr_sigma.last=1", "batch=512"])
            .plenoxels_config()
            .unwrap();
        assert_eq!(
            (cfg.tv_sigma, cfg.lr_sigma.last, cfg.batch),
            (1e-6, 1.0, 512)
        );
        let err = |set: &[&str]| format!("{:#}", opts(set).plenoxels_config().unwrap_err());
        assert!(
            err(&["tv_sigmaa=1"]).contains("--plenoxels-set tv_sigmaa=1: no configuration field")
        );
        assert!(err(&["tv_until_upsample=1"]).contains("is false, not 1"));
        assert!(err(&["tv_fraction=2"]).contains("tv_fraction must be in [0, 1]"));
        // Issue 44: the checks the flags have, whichever flag set the value.
        for (set, want) in [
            ("iters=0", "iters must be at least 1"),
            ("res=5000", "8 ..= 1024"),
            ("upsample=[[3,4000]]", "8 ..= 1024"),
            ("upsample=[[3,2]]", "8 ..= 1024"),
            ("upsample=[[5000,64]]", "past the last step"),
            ("upsample=[[10,128],[5,256]]", "later step"),
            ("lr_sigma.init=-30", "lr_sigma.init must be finite and ≥ 0"),
        ] {
            let e = err(&[set]);
            assert!(
                e.contains(&format!("--plenoxels-set {set}")) && e.contains(want),
                "{set}: {e}"
            );
        }
        let huge = opts(&["batch=4000000000"]);
        let cfg = huge.plenoxels_config().unwrap();
        let e = format!("{:#}", huge.check_plenoxels_memory(&cfg, 1.0).unwrap_err());
        assert!(
            e.contains("--plenoxels-set batch=4000000000") && e.contains("memory"),
            "{e}"
        );
        let stage2 = TrainOptions {
            set: vec!["iters=0".into()],
            ..TrainOptions::new(Stage::Surface, "d".into(), "o".into())
        };
        let e = format!("{:#}", stage2.surface_config(64).unwrap_err());
        assert!(
            e.contains("--set iters=0") && e.contains("at least 1"),
            "{e}"
        );
        let surface = TrainOptions {
            plenoxels_set: vec!["tv_sigma=0".into()],
            ..TrainOptions::new(Stage::Surface, "d".into(), "o".into())
        };
        let refused = format!("{:#}", surface.check_stage_flags().unwrap_err());
        assert!(refused.contains("--plenoxels-set is not used by --stage surface"));
        // Two flags for stage 2's steps: one would be ignored.
        let both = TrainOptions {
            iters: Some(50),
            surface_iters: Some(10),
            ..TrainOptions::new(Stage::Surface, "d".into(), "o".into())
        };
        let refused = format!("{:#}", both.check_stage_flags().unwrap_err());
        assert!(refused.contains("--iters and --surface-iters"), "{refused}");
        let allow = TrainOptions {
            allow_other_data: true,
            ..TrainOptions::new(Stage::Plenoxels, "d".into(), "o".into())
        };
        let refused = format!("{:#}", allow.check_stage_flags().unwrap_err());
        assert!(
            refused.contains("--allow-other-data applies with --resume"),
            "{refused}"
        );
    }
}
