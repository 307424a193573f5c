//! The pipeline steps of `demo` and `bench time-vs-error`, each one a user-facing subcommand run
//! in-process: the step builds an argument vector, parses it with the binary's own clap [`Cli`],
//! and runs it through the binary's dispatch ([`super::super::run`]), so the demo exercises
//! exactly the commands a user types. Results are read back from what the commands write
//! (`metrics.json`) or, for `eval`, from the metrics its handler returns.

use super::super::{backend_gpu, run as dispatch, Cli, Command};
use crate::backend::Backend;
use crate::cli::extract::DEFAULT_RAYS_PER_AXIS;
use crate::eval::Metrics;
use crate::scene::SceneKind;
use crate::train::{Category, Preset};
use anyhow::{anyhow, bail, Context, Result};
use clap::Parser;
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

/// Runs subcommands in-process with one resolved backend (`cpu` or `vulkan`) and `--device`.
#[derive(Clone, Debug)]
pub struct Invoker {
    /// The backend passed to every training/extraction command.
    pub backend: Backend,
    device: Option<usize>,
    /// `extract --rays-per-axis` for every extraction.
    pub rays_per_axis: u32,
    /// `train --preset` for both stages.
    pub preset: Preset,
    /// `train --seed` for both stages.
    pub seed: u64,
}

/// Size of a generated scene (`make-scene` arguments).
#[derive(Clone, Copy, Debug)]
pub struct SceneSize {
    pub image_res: u32,
    pub views: u32,
    pub spp: u32,
    pub gt_spacing: f64,
}

/// Stage-1 size overrides (`train` arguments; `None` keeps the preset's value).
#[derive(Clone, Copy, Debug, Default)]
pub struct TrainSize {
    pub res: Option<u32>,
    pub iters: Option<u32>,
    pub batch: Option<u32>,
}

/// A finished training run, as its `metrics.json` reports it.
#[derive(Clone, Debug)]
pub struct TrainedRun {
    pub dir: PathBuf,
    /// Wall time of the `train` command (load, training, checkpoints, test renders).
    pub wall_s: f64,
    pub test_psnr: f64,
    pub train_rays_per_s: f64,
}

/// Everything a step's argument vector can hold.
fn os<S: AsRef<std::ffi::OsStr>>(s: S) -> OsString {
    s.as_ref().to_os_string()
}

impl Invoker {
    /// Resolve `--backend auto` once (the same rule as every command: Vulkan on a GPU, the CPU
    /// twins on lavapipe or without a device), so the steps do not each probe the device.
    pub fn new(backend: Backend, cli: &Cli) -> Result<Invoker> {
        let mut slot = None;
        let resolved = match backend {
            Backend::Auto => match backend_gpu(Backend::Auto, cli, &mut slot)? {
                Some(_) => Backend::Vulkan,
                None => Backend::Cpu,
            },
            chosen => chosen,
        };
        Ok(Invoker {
            backend: resolved,
            device: cli.device,
            rays_per_axis: DEFAULT_RAYS_PER_AXIS,
            preset: Preset::Fast,
            seed: 0,
        })
    }

    /// The same invoker, extracting with R² virtual rays per axis and cell.
    pub fn with_rays_per_axis(self, rays_per_axis: u32) -> Invoker {
        Invoker {
            rays_per_axis,
            ..self
        }
    }

    /// An invoker that passes `--backend cpu` (`vulkan: false`) or `--backend vulkan`.
    pub fn fixed(vulkan: bool, cli: &Cli) -> Invoker {
        Invoker {
            backend: if vulkan {
                Backend::Vulkan
            } else {
                Backend::Cpu
            },
            device: cli.device,
            rays_per_axis: DEFAULT_RAYS_PER_AXIS,
            preset: Preset::Fast,
            seed: 0,
        }
    }

    /// The same invoker, training with `--preset preset --seed seed`.
    pub fn with_schedule(self, preset: Preset, seed: u64) -> Invoker {
        Invoker {
            preset,
            seed,
            ..self
        }
    }

    /// The parsed command line `alphasurf [--device N] ARGS…`.
    pub fn parse(&self, args: &[OsString]) -> Result<Cli> {
        let mut full = vec![os("alphasurf")];
        if let Some(d) = self.device {
            full.extend([os("--device"), os(d.to_string())]);
        }
        full.extend(args.iter().cloned());
        Cli::try_parse_from(&full).map_err(|e| {
            anyhow!(
                "`alphasurf {}` is not a valid command here: {}",
                show(args),
                e.render().to_string().trim()
            )
        })
    }

    /// Run `alphasurf ARGS…` through the binary's dispatch; returns its wall time in seconds.
    pub fn run(&self, args: &[OsString]) -> Result<f64> {
        let cli = self.parse(args)?;
        let t = Instant::now();
        let code = dispatch(cli).with_context(|| format!("`alphasurf {}`", show(args)))?;
        if code != ExitCode::SUCCESS {
            bail!("`alphasurf {}` exited with a failure code", show(args));
        }
        Ok(t.elapsed().as_secs_f64())
    }

    /// `make-scene`.
    pub fn make_scene(&self, kind: SceneKind, out: &Path, size: &SceneSize) -> Result<f64> {
        self.run(&[
            os("make-scene"),
            os("--kind"),
            os(kind.name()),
            os("--out"),
            os(out),
            os("--res"),
            os(size.image_res.to_string()),
            os("--views"),
            os(size.views.to_string()),
            os("--spp"),
            os(size.spp.to_string()),
            os("--gt-spacing"),
            os(size.gt_spacing.to_string()),
        ])
    }

    /// `train --stage plenoxels --preset P --seed S` (with the size overrides).
    pub fn train_plenoxels(
        &self,
        data: &Path,
        out: &Path,
        size: &TrainSize,
        progress: bool,
    ) -> Result<TrainedRun> {
        let mut a = vec![
            os("train"),
            os("--stage"),
            os("plenoxels"),
            os("--data"),
            os(data),
            os("--out"),
            os(out),
            os("--preset"),
            os(self.preset.name()),
            os("--backend"),
            os(self.backend.name()),
            os("--seed"),
            os(self.seed.to_string()),
            // A rerun replaces the runs it made before (only runs: never other files).
            os("--overwrite"),
        ];
        push_size(&mut a, size);
        if !progress {
            a.push(os("--quiet"));
        }
        let wall_s = self.run(&a)?;
        read_run(out, wall_s)
    }

    /// Stage 2: `train --stage surface --init STAGE1_RUN` (αSurf), on the stage-1 run `init`,
    /// with `--set` overrides.
    #[allow(clippy::too_many_arguments)]
    pub fn train_surface(
        &self,
        init: &Path,
        data: &Path,
        out: &Path,
        category: Category,
        iters: Option<u32>,
        set: &[String],
        progress: bool,
    ) -> Result<TrainedRun> {
        let mut a = vec![
            os("train"),
            os("--stage"),
            os("surface"),
            os("--init"),
            os(init),
            os("--data"),
            os(data),
            os("--out"),
            os(out),
            os("--category"),
            os(category.name()),
            os("--preset"),
            os(self.preset.name()),
            os("--backend"),
            os(self.backend.name()),
            os("--seed"),
            os(self.seed.to_string()),
            // A rerun replaces the runs it made before (only runs: never other files).
            os("--overwrite"),
        ];
        push_size(
            &mut a,
            &TrainSize {
                iters,
                ..Default::default()
            },
        );
        for kv in set {
            a.extend([os("--set"), os(kv)]);
        }
        if !progress {
            a.push(os("--quiet"));
        }
        let wall_s = self.run(&a)?;
        read_run(out, wall_s)
    }

    /// `extract --run RUN --out PLY [--levels …]`; returns its wall time.
    pub fn extract(&self, run: &Path, ply: &Path, levels: Option<&[f32]>) -> Result<f64> {
        let mut a = vec![
            os("extract"),
            os("--run"),
            os(run),
            os("--out"),
            os(ply),
            os("--backend"),
            os(self.backend.name()),
            os("--rays-per-axis"),
            os(self.rays_per_axis.to_string()),
        ];
        if let Some(l) = levels {
            let list: Vec<String> = l.iter().map(|v| v.to_string()).collect();
            a.extend([os("--levels"), os(list.join(","))]);
        }
        self.run(&a)
    }

    /// `eval --pred PLY --gt GT`: the metrics its handler printed and returned.
    pub fn eval(&self, pred: &Path, gt: &Path) -> Result<Metrics> {
        let a = [os("eval"), os("--pred"), os(pred), os("--gt"), os(gt)];
        match self.parse(&a)?.command {
            Command::Eval(args) => super::super::eval::run(&args),
            other => bail!("`alphasurf {}` parsed as {other:?}", show(&a)),
        }
    }
}

fn push_size(a: &mut Vec<OsString>, size: &TrainSize) {
    for (flag, v) in [
        ("--res", size.res),
        ("--iters", size.iters),
        ("--batch", size.batch),
    ] {
        if let Some(v) = v {
            a.extend([os(flag), os(v.to_string())]);
        }
    }
}

/// The command line as a user would type it.
fn show(args: &[OsString]) -> String {
    args.iter()
        .map(|a| a.to_string_lossy().into_owned())
        .collect::<Vec<_>>()
        .join(" ")
}

/// Read a training run's metrics.json.
pub fn read_run(dir: &Path, wall_s: f64) -> Result<TrainedRun> {
    let path = dir.join("metrics.json");
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let v: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
    let num = |k: &str| {
        v[k].as_f64()
            .with_context(|| format!("{}: no number {k:?}", path.display()))
    };
    Ok(TrainedRun {
        dir: dir.to_path_buf(),
        wall_s,
        test_psnr: num("test_psnr")?,
        train_rays_per_s: num("train_rays_per_s")?,
    })
}
