//! The pipeline steps of `demo` and the benchmarks (`bench time-vs-error`, `bench accuracy`):
//! make-scene, stage 1, stage 2, extract and eval as library calls on one resolved backend and
//! one schedule.

use super::evaluate::{evaluate, EvaluateOptions, GroundTruth};
use super::extract::{extract, extract_levels, ExtractOptions, LevelJob, DEFAULT_RAYS_PER_AXIS};
use super::metrics::{self, PlenoxelsMetrics};
use super::train::train;
use super::train_options::{Stage, TrainOptions};
use super::train_run::Trained;
use crate::backend::Backend;
use crate::data::ndc::Space;
use crate::data::BackgroundMode;
use crate::eval::Metrics;
use crate::gpu::Gpu;
use crate::scene::{generate, GenerateOptions, SceneKind};
use crate::train::{Category, PlenoxelsConfig, Preset, SurfaceConfig};
use anyhow::{bail, Result};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Size of a generated scene.
#[derive(Clone, Copy, Debug)]
pub struct SceneSize {
    pub image_res: u32,
    pub views: u32,
    /// Samples per pixel along each axis.
    pub spp: u32,
    /// Ground-truth point spacing, Blender units.
    pub gt_spacing: f64,
}

/// Stage-1 overrides (`None` or empty keeps the preset's values).
#[derive(Clone, Debug, Default)]
pub struct PlenoxelsOverrides {
    /// Final grid resolution.
    pub res: Option<u32>,
    pub iters: Option<u32>,
    /// Rays per batch.
    pub batch: Option<u32>,
    /// `train --plenoxels-set KEY=VALUE` overrides, in order.
    pub set: Vec<String>,
}

/// Stage-2 choices (`None` or empty keeps the preset's values).
#[derive(Clone, Debug)]
pub struct SurfaceOverrides {
    pub category: Category,
    /// Stage-2 steps.
    pub iters: Option<u32>,
    /// `train --set KEY=VALUE` overrides, in order.
    pub set: Vec<String>,
}

/// A finished training run.
#[derive(Clone, Debug)]
pub struct TrainedRun {
    pub dir: PathBuf,
    /// Wall time of the training call (load, training, checkpoints, test renders).
    pub wall_s: f64,
    /// Mean test-view PSNR, dB.
    pub test_psnr: f64,
    pub test_psnr_per_view: Vec<f64>,
    pub train_rays_per_s: f64,
}

impl TrainedRun {
    /// The run in `dir` that took `wall_s`, with its test PSNR (mean and per view) and training
    /// rays/s.
    fn new(dir: &Path, wall_s: f64, psnr: (f64, Vec<f64>), train_rays_per_s: f64) -> TrainedRun {
        TrainedRun {
            dir: dir.to_path_buf(),
            wall_s,
            test_psnr: psnr.0,
            test_psnr_per_view: psnr.1,
            train_rays_per_s,
        }
    }

    /// The finished stage-1 run in `dir`, from its metrics.json; `wall_s` as recorded elsewhere.
    pub fn read_plenoxels(dir: &Path, wall_s: f64) -> Result<TrainedRun> {
        let m: PlenoxelsMetrics = metrics::read(dir)?;
        let psnr = (m.test_psnr, m.test_psnr_per_view);
        Ok(TrainedRun::new(dir, wall_s, psnr, m.train_rays_per_s))
    }
}

/// Runs the steps on one device (`None`: the CPU twins) with one schedule.
#[derive(Clone, Copy)]
pub struct Steps<'g> {
    /// The Vulkan device the kernels run on (`None`: the CPU twins).
    pub gpu: Option<&'g Gpu>,
    /// `extract --rays-per-axis` of every extraction.
    pub rays_per_axis: u32,
    /// `train --preset` of both stages.
    pub preset: Preset,
    /// `train --seed` of both stages.
    pub seed: u64,
    /// Progress bars (or, off a terminal, a line every 10 %) while training.
    pub progress: bool,
    /// `train --space` of stage 1 (stage 2 takes its stage-1 run's).
    pub space: Space,
    /// `train --background` of both stages.
    pub background: BackgroundMode,
}

impl<'g> Steps<'g> {
    /// Steps on `gpu` with preset `fast`, seed 0 and the default extraction lattice.
    pub fn new(gpu: Option<&'g Gpu>) -> Steps<'g> {
        Steps {
            gpu,
            rays_per_axis: DEFAULT_RAYS_PER_AXIS,
            preset: Preset::Fast,
            seed: 0,
            progress: true,
            space: Space::Auto,
            background: BackgroundMode::Auto,
        }
    }

    /// The same steps without progress bars.
    pub fn quiet(self) -> Steps<'g> {
        Steps {
            progress: false,
            ..self
        }
    }

    /// Where the steps run: `vulkan` or `cpu`.
    pub fn backend(&self) -> Backend {
        match self.gpu {
            Some(_) => Backend::Vulkan,
            None => Backend::Cpu,
        }
    }

    /// `make-scene`; returns its wall time.
    pub fn make_scene(&self, kind: SceneKind, out: &Path, size: &SceneSize) -> Result<f64> {
        let t = Instant::now();
        let r = generate(
            out,
            &GenerateOptions {
                kind,
                res: size.image_res,
                views: size.views,
                seed: 0,
                spp_side: size.spp,
                gt_spacing: size.gt_spacing,
                progress: std::io::stderr().is_terminal(),
                // The scene folder belongs to the command's own output (demo, bench).
                overwrite: true,
            },
        )?;
        eprintln!(
            "wrote {} ({} views, {} gt points) to {} in {:.2} s",
            kind.name(),
            r.views,
            r.gt_points,
            out.display(),
            r.total_s
        );
        Ok(t.elapsed().as_secs_f64())
    }

    /// The options of a training step that replaces the run in `out` (only a run: never other
    /// files).
    fn train_options(&self, stage: Stage, data: &Path, out: &Path) -> TrainOptions {
        TrainOptions {
            preset: Some(self.preset),
            backend: self.backend(),
            seed: self.seed,
            overwrite: true,
            quiet: !self.progress,
            space: self.space,
            background: self.background,
            ..TrainOptions::new(stage, data.to_path_buf(), out.to_path_buf())
        }
    }

    fn plenoxels_options(
        &self,
        data: &Path,
        out: &Path,
        stage1: &PlenoxelsOverrides,
    ) -> TrainOptions {
        TrainOptions {
            res: stage1.res,
            iters: stage1.iters,
            batch: stage1.batch,
            plenoxels_set: stage1.set.clone(),
            ..self.train_options(Stage::Plenoxels, data, out)
        }
    }

    /// The configuration `train_plenoxels` trains with these overrides (this build's presets).
    pub fn plenoxels_config(
        &self,
        data: &Path,
        stage1: &PlenoxelsOverrides,
    ) -> Result<PlenoxelsConfig> {
        self.plenoxels_options(data, Path::new(""), stage1)
            .plenoxels_config()
    }

    /// Stage 1: `train --stage plenoxels` with the overrides.
    pub fn train_plenoxels(
        &self,
        data: &Path,
        out: &Path,
        stage1: &PlenoxelsOverrides,
    ) -> Result<TrainedRun> {
        let opts = self.plenoxels_options(data, out, stage1);
        let t = Instant::now();
        let done = train(&opts, self.gpu)?.stage1;
        let wall_s = t.elapsed().as_secs_f64();
        match done {
            Some(Trained::Done(m)) => {
                let psnr = (m.test_psnr, m.test_psnr_per_view);
                Ok(TrainedRun::new(out, wall_s, psnr, m.train_rays_per_s))
            }
            _ => bail!("stage 1 into {} trained nothing", out.display()),
        }
    }

    fn surface_options(
        &self,
        init: &Path,
        data: &Path,
        out: &Path,
        stage2: &SurfaceOverrides,
    ) -> TrainOptions {
        TrainOptions {
            init: Some(init.to_path_buf()),
            category: Some(stage2.category),
            iters: stage2.iters,
            set: stage2.set.clone(),
            ..self.train_options(Stage::Surface, data, out)
        }
    }

    /// The configuration `train_surface` trains from a stage-1 grid of `grid_n`³ vertices with
    /// these overrides (this build's presets).
    pub fn surface_config(
        &self,
        data: &Path,
        stage2: &SurfaceOverrides,
        grid_n: u32,
    ) -> Result<SurfaceConfig> {
        let none = Path::new("");
        self.surface_options(none, data, none, stage2)
            .surface_config(grid_n)
    }

    /// Stage 2 (αSurf): `train --stage surface --init STAGE1_RUN` with the overrides.
    pub fn train_surface(
        &self,
        init: &Path,
        data: &Path,
        out: &Path,
        stage2: &SurfaceOverrides,
    ) -> Result<TrainedRun> {
        let opts = self.surface_options(init, data, out, stage2);
        let t = Instant::now();
        let done = train(&opts, self.gpu)?.stage2;
        let wall_s = t.elapsed().as_secs_f64();
        match done {
            Some(Trained::Done(m)) => {
                let psnr = (m.test_psnr, m.test_psnr_per_view);
                Ok(TrainedRun::new(out, wall_s, psnr, m.train_rays_per_s))
            }
            _ => bail!("stage 2 into {} trained nothing", out.display()),
        }
    }

    /// `extract --run RUN --out PLY [--levels …]`; returns its wall time.
    pub fn extract(&self, run: &Path, ply: &Path, levels: Option<&[f32]>) -> Result<f64> {
        let opts = ExtractOptions {
            levels: levels.map(<[f32]>::to_vec),
            rays_per_axis: self.rays_per_axis,
            backend: self.backend(),
            ..ExtractOptions::for_run(run.to_path_buf(), ply.to_path_buf())
        };
        let t = Instant::now();
        extract(&opts, self.gpu)?;
        Ok(t.elapsed().as_secs_f64())
    }

    /// `extract --run RUN --mesh PLY [--levels …]`; returns its wall time.
    pub fn extract_mesh(&self, run: &Path, mesh: &Path, levels: Option<&[f32]>) -> Result<f64> {
        let opts = ExtractOptions {
            out: None,
            mesh: Some(mesh.to_path_buf()),
            levels: levels.map(<[f32]>::to_vec),
            backend: self.backend(),
            ..ExtractOptions::for_run(run.to_path_buf(), mesh.to_path_buf())
        };
        let t = Instant::now();
        extract(&opts, self.gpu)?;
        Ok(t.elapsed().as_secs_f64())
    }

    /// `eval --pred PLY --gt GT`.
    pub fn eval(&self, pred: &Path, gt: &Path) -> Result<Metrics> {
        Ok(evaluate(&EvaluateOptions::new(pred.to_path_buf(), gt.to_path_buf()))?.metrics)
    }

    /// The cloud `gt` read, thinned and indexed once, to [`Steps::eval_against`] many clouds.
    pub fn ground_truth(&self, gt: &Path) -> Result<GroundTruth> {
        GroundTruth::load(&EvaluateOptions::new(PathBuf::new(), gt.to_path_buf()))
    }

    /// `eval --pred PLY --gt GT` against a ground truth loaded once.
    pub fn eval_against(&self, pred: &Path, gt: &GroundTruth) -> Result<Metrics> {
        let opts = EvaluateOptions::new(pred.to_path_buf(), gt.path().to_path_buf());
        Ok(gt.score(&opts)?.metrics)
    }

    /// `extract --levels L --trim-hidden on|off --out P` for each job from one load of the
    /// stage-1 run `run`; each job's result with its seconds.
    pub fn extract_levels(&self, run: &Path, jobs: &[LevelJob]) -> Result<Vec<Result<f64>>> {
        let opts = ExtractOptions {
            rays_per_axis: self.rays_per_axis,
            backend: self.backend(),
            out: None,
            ..ExtractOptions::for_run(run.to_path_buf(), PathBuf::new())
        };
        let done = extract_levels(&opts, jobs, self.gpu)?;
        Ok(done.into_iter().map(|r| r.map(|(_, s)| s)).collect())
    }
}
