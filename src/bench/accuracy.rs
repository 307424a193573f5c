//! `alphasurf bench accuracy`: the method scored on a set of scenes with ground truth (the
//! development set). For each scene: stage 1, the Plenoxels level-set sweep (extract + eval at
//! every level of [`LEVELS`]), stage 2, αSurf's extraction and eval — the pipeline's library
//! calls (`pipeline::steps`). Then one table: scene, category, αSurf's Chamfer, the best
//! Plenoxels level of that scene, Plenoxels at the category's fixed level (the paper's protocol:
//! one level per category, the one with the best mean over the set's scenes of that category),
//! αSurf / best level, F1 of both, stage-1 and stage-2 test PSNR and wall time; then the category
//! means. Each finished scene leaves `OUT/SCENE/result.json`; a rerun with the same settings
//! reuses it. A finished stage-1 run is reused while its settings hold, also from another output
//! (`--stage1-from`), so stage-2 changes are compared on the same stage-1 grids. "Settings" are
//! the flags and the configuration they give in this build: a run trained under other presets
//! (an older build) is trained again, never scored as this build's.

use crate::backend::Backend;
use crate::data::ndc::Space;
use crate::data::{BackgroundMode, Dataset, LoadOptions};
use crate::pipeline::demo::{
    alphasurf_row, plenoxels_levels, plenoxels_levels_trimmed, Row, LEVELS,
};
use crate::pipeline::metrics::{
    self, PlenoxelsMetrics, PlenoxelsSeconds, SurfaceMetrics, SurfaceSeconds,
};
use crate::pipeline::steps::{PlenoxelsOverrides, Steps, SurfaceOverrides, TrainedRun};
use crate::pipeline::Devices;
use crate::run::interrupt;
use crate::train::{Category, PlenoxelsConfig, Preset, SurfaceConfig};
use anyhow::{bail, ensure, Context, Result};
use clap::ValueEnum;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `bench accuracy`.
#[derive(clap::Args, Debug)]
pub struct AccuracyArgs {
    /// Scene folders (NeRF-synthetic layout with `gt_points.ply`), e.g. the development set
    /// `../shared/fixtures/*/`. Each scene's category comes from its folder name's first word
    /// (`thin_lyre` → thin; `capture_…`, a photographed capture, → real) unless `--category` is
    /// given.
    #[arg(long, required = true, num_args = 1..)]
    pub data: Vec<PathBuf>,
    /// Stage-2 category for every scene.
    #[arg(long, value_enum)]
    pub category: Option<Category>,
    /// Final stage-1 grid resolution N (default: the preset's).
    #[arg(long, value_parser = clap::value_parser!(u32).range(8..=1024))]
    pub res: Option<u32>,
    /// Stage-1 steps (default: the preset's).
    #[arg(long)]
    pub iters: Option<u32>,
    /// Rays per batch of both stages (default: the presets'); `--surface-set batch=N` sets
    /// stage 2's alone.
    #[arg(long)]
    pub batch: Option<u32>,
    /// Schedule of both stages.
    #[arg(long, value_enum, default_value_t = Preset::Fast)]
    pub preset: Preset,
    /// Seed of both stages (the ray batches, the regularisers' chunks).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Stage-2 steps (default: the preset's).
    #[arg(long)]
    pub surface_iters: Option<u32>,
    /// Stage-2 configuration override, passed on as `train --set KEY=VALUE`. Repeatable.
    #[arg(long, value_name = "KEY=VALUE")]
    pub surface_set: Vec<String>,
    /// Stage-1 configuration override, passed on as `train --plenoxels-set KEY=VALUE`.
    /// Repeatable.
    #[arg(long, value_name = "KEY=VALUE")]
    pub plenoxels_set: Vec<String>,
    /// Where the kernels run (resolved once).
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    pub backend: Backend,
    /// Where each scene's grid lies, as `train --space` takes it (`auto`: NDC for a
    /// forward-facing capture).
    #[arg(long, value_enum, default_value_t = Space::Auto)]
    pub space: Space,
    /// What rays are composited on, as `train --background` takes it (`spheres`: a 360°
    /// capture's room on learned spheres around the grid box).
    #[arg(long, value_enum, default_value_t = BackgroundMode::Auto)]
    pub background: BackgroundMode,
    /// Output directory: one folder per scene (its runs, clouds and result.json) and
    /// accuracy.json. Default: runs/accuracy-N-PRESET-sSEED.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Reuse the stage-1 runs of an earlier `bench accuracy` output (DIR/SCENE/plenoxels) with
    /// the same data, resolution, preset and backend, instead of training stage 1. Refused when
    /// a run's recorded configuration is not the one this build's preset gives (an older build).
    #[arg(long, value_name = "DIR")]
    pub stage1_from: Option<PathBuf>,
    /// Print one JSON object with every scene as the last stdout line.
    #[arg(long)]
    pub json: bool,
}

/// What a stage-1 run depends on (`plenoxels/stage1.json`, with its wall time).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlenoxelsSettings {
    pub data: PathBuf,
    pub res: Option<u32>,
    pub iters: Option<u32>,
    pub batch: Option<u32>,
    pub preset: Preset,
    pub seed: u64,
    pub backend: Backend,
    /// `--plenoxels-set` overrides (absent from records written before it).
    #[serde(default)]
    pub set: Vec<String>,
    /// `--space` (absent from records written before it: `auto`, which was the box then).
    #[serde(default)]
    pub space: Space,
    /// `--background` (absent from records written before it: white).
    #[serde(default = "BackgroundMode::unrecorded")]
    pub background: BackgroundMode,
}

impl PlenoxelsSettings {
    /// The stage-1 flags these settings hold.
    fn overrides(&self) -> PlenoxelsOverrides {
        PlenoxelsOverrides {
            res: self.res,
            iters: self.iters,
            batch: self.batch,
            set: self.set.clone(),
        }
    }
}

/// A finished stage-1 run and its level sweep (`plenoxels/stage1.json`).
#[derive(Serialize, Deserialize)]
struct PlenoxelsRecord {
    settings: PlenoxelsSettings,
    wall_s: f64,
    levels: Vec<LevelScore>,
    /// The sweep's wall time (0 in records written before it).
    #[serde(default)]
    levels_s: f64,
}

/// The level with the lowest finite Chamfer distance.
fn best_of(levels: &[LevelScore]) -> Option<&LevelScore> {
    levels
        .iter()
        .filter_map(|l| Some((l, l.chamfer_e2.filter(|c| c.is_finite())?)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(l, _)| l)
}

impl PlenoxelsRecord {
    /// The level with the lowest finite Chamfer distance.
    fn best(&self) -> Option<&LevelScore> {
        best_of(&self.levels)
    }
}

/// What a scene's figures depend on; a stored result is reused only when this matches.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Settings {
    pub stage1: PlenoxelsSettings,
    pub category: Category,
    /// Stage 2's seed.
    pub seed: u64,
    pub surface_iters: Option<u32>,
    pub surface_set: Vec<String>,
}

/// One Plenoxels level of a scene.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct LevelScore {
    pub level: f32,
    pub chamfer_e2: Option<f64>,
    pub f1: Option<f64>,
}

/// One scene's figures (`OUT/SCENE/result.json`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SceneResult {
    pub scene: String,
    pub settings: Settings,
    /// Every level of the sweep.
    pub levels: Vec<LevelScore>,
    /// The same sweep with αSurf's own extraction rules for thin scenes (hidden cells trimmed,
    /// `extract --trim-hidden on`; thin sheets centred, `--sheets on`; empty on other
    /// categories): the like-for-like baseline.
    #[serde(default)]
    pub trimmed_levels: Vec<LevelScore>,
    pub best_level: Option<f32>,
    pub best_chamfer_e2: Option<f64>,
    pub best_f1: Option<f64>,
    pub alphasurf_chamfer_e2: Option<f64>,
    pub alphasurf_f1: Option<f64>,
    pub stage1_psnr: f64,
    pub stage2_psnr: Option<f64>,
    /// Stage 1 + stage 2 training wall time.
    pub train_wall_s: f64,
    /// The whole scene: training, every extraction and eval.
    pub wall_s: f64,
    /// Why stage 2 or its evaluation failed.
    pub error: Option<String>,
    /// Where the wall time went (absent in results written before it).
    #[serde(default)]
    pub time: Option<SceneTime>,
}

/// Where a scene's wall time went, seconds: each training run's phases (its metrics.json) and
/// the scoring around them.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SceneTime {
    pub stage1: Option<PlenoxelsSeconds>,
    /// Extraction and eval of every level of stage 1 (0 when its record predates the timing).
    pub levels_s: f64,
    /// The same with the levels' hidden cells trimmed (thin scenes).
    pub trimmed_levels_s: f64,
    pub stage2: Option<SurfaceSeconds>,
    /// αSurf's extraction and eval.
    pub alphasurf_score_s: f64,
}

impl SceneTime {
    /// One line: each part's seconds, the training runs' phases in brackets.
    pub fn line(&self) -> String {
        let s1 = self.stage1.as_ref().map_or("—".into(), |t| {
            format!(
                "{:.1} s (load {:.1}, train {:.1}, upsample {:.1}, checkpoints {:.1}, test renders {:.1})",
                t.total, t.load, t.train, t.upsample, t.checkpoint, t.render_test
            )
        });
        let s2 = self.stage2.as_ref().map_or("—".into(), |t| {
            format!(
                "{:.1} s (load {:.1}, train {:.1}, checkpoints {:.1}, test renders {:.1})",
                t.total, t.load, t.train, t.checkpoint, t.render_test
            )
        });
        format!(
            "stage 1 {s1}; level sweep {:.1} s, trimmed {:.1} s; stage 2 {s2}; αSurf extract + eval {:.1} s",
            self.levels_s, self.trimmed_levels_s, self.alphasurf_score_s
        )
    }
}

impl SceneResult {
    /// αSurf's Chamfer over the best level's.
    pub fn ratio(&self) -> Option<f64> {
        Some(self.alphasurf_chamfer_e2? / self.best_chamfer_e2?)
    }

    /// The best level of the trimmed sweep.
    pub fn trimmed_best(&self) -> Option<&LevelScore> {
        best_of(&self.trimmed_levels)
    }

    /// αSurf's Chamfer over the best trimmed level's.
    pub fn trimmed_ratio(&self) -> Option<f64> {
        Some(self.alphasurf_chamfer_e2? / self.trimmed_best()?.chamfer_e2?)
    }

    fn level(&self, l: f32) -> Option<f64> {
        self.levels
            .iter()
            .find(|s| s.level == l)
            .and_then(|s| s.chamfer_e2)
    }
}

/// The set's figures: every scene, and per category the fixed level and the means.
#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    pub scenes: Vec<SceneResult>,
    pub categories: Vec<CategoryMean>,
}

/// Means over one category's scenes.
#[derive(Clone, Debug, Serialize)]
pub struct CategoryMean {
    pub category: Category,
    pub scenes: usize,
    /// The level with the lowest mean Chamfer over these scenes (the paper's fixed level).
    pub fixed_level: Option<f32>,
    pub fixed_level_chamfer_e2: Option<f64>,
    pub best_chamfer_e2: Option<f64>,
    pub alphasurf_chamfer_e2: Option<f64>,
    pub ratio: Option<f64>,
    /// The mean of the scenes' ratios to their best trimmed level (every scene has one).
    pub trimmed_ratio: Option<f64>,
    pub stage1_psnr: f64,
    pub stage2_psnr: Option<f64>,
}

/// The folder-name word of a photographed capture: category real when it trains in NDC (the
/// supplement's real-world set-up, forward-facing), translucent in a box (a 360° capture on
/// background spheres: the grid in dataset units, as the film scenes'; docs/results.md).
const CAPTURE_WORD: &str = "capture";

/// The category of a scene folder: `--category`, else its name's first word (a category's name,
/// or [`CAPTURE_WORD`]: real or translucent as `in_ndc` says where it trains).
pub fn scene_category(
    dir: &Path,
    given: Option<Category>,
    in_ndc: impl FnOnce() -> Result<bool>,
) -> Result<Category> {
    if let Some(c) = given {
        return Ok(c);
    }
    let name = scene_name(dir);
    let first = name.split(['_', '-']).next().unwrap_or("");
    if first == CAPTURE_WORD {
        return Ok(if in_ndc()? {
            Category::Real
        } else {
            Category::Translucent
        });
    }
    match Category::value_variants()
        .iter()
        .find(|c| c.name() == first)
    {
        Some(&c) => Ok(c),
        None => bail!(
            "{}: cannot tell the scene's category from its folder name (expected it to start \
             with one of {}, {CAPTURE_WORD} and '_'); pass --category",
            dir.display(),
            Category::value_variants()
                .iter()
                .map(|c| c.name())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

fn scene_name(dir: &Path) -> String {
    dir.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| dir.display().to_string())
}

/// Mean of the values when every one is present.
fn mean_all(v: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let v: Option<Vec<f64>> = v.collect();
    let v = v?;
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// Category means and fixed levels over the scenes.
pub fn summarise(scenes: Vec<SceneResult>) -> Summary {
    let mut by_cat: BTreeMap<Category, Vec<&SceneResult>> = BTreeMap::new();
    for s in &scenes {
        by_cat.entry(s.settings.category).or_default().push(s);
    }
    let categories = by_cat
        .into_iter()
        .map(|(category, ss)| {
            let fixed = LEVELS
                .iter()
                .filter_map(|&l| Some((l, mean_all(ss.iter().map(|s| s.level(l)))?)))
                .min_by(|a, b| a.1.total_cmp(&b.1));
            CategoryMean {
                scenes: ss.len(),
                fixed_level: fixed.map(|f| f.0),
                fixed_level_chamfer_e2: fixed.map(|f| f.1),
                best_chamfer_e2: mean_all(ss.iter().map(|s| s.best_chamfer_e2)),
                alphasurf_chamfer_e2: mean_all(ss.iter().map(|s| s.alphasurf_chamfer_e2)),
                ratio: mean_all(ss.iter().map(|s| s.ratio())),
                trimmed_ratio: mean_all(ss.iter().map(|s| s.trimmed_ratio())),
                stage1_psnr: ss.iter().map(|s| s.stage1_psnr).sum::<f64>() / ss.len() as f64,
                stage2_psnr: mean_all(ss.iter().map(|s| s.stage2_psnr)),
                category,
            }
        })
        .collect();
    Summary { scenes, categories }
}

fn num(v: Option<f64>, prec: usize) -> String {
    match v {
        Some(x) if x.is_finite() => format!("{x:.prec$}"),
        _ => "—".into(),
    }
}

/// The table: one row per scene, then one per category (markdown).
pub fn table(s: &Summary) -> String {
    let fixed: BTreeMap<Category, Option<f32>> = s
        .categories
        .iter()
        .map(|c| (c.category, c.fixed_level))
        .collect();
    let mut t = String::from(
        "| scene | category | αSurf | best Plen (σ) | Plen at the category's σ | ratio | vs levels trimmed (σ) | F1 αSurf / best | PSNR stage 1 → 2 | wall |\n\
         |---|---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for r in &s.scenes {
        let fl = fixed.get(&r.settings.category).copied().flatten();
        t += &format!(
            "| {} | {} | {} | {} ({}) | {} ({}) | {}× | {} | {} / {} | {:.2} → {} dB | {:.0} s |\n",
            r.scene,
            r.settings.category,
            num(r.alphasurf_chamfer_e2, 4),
            num(r.best_chamfer_e2, 4),
            r.best_level.map_or("—".into(), |l| l.to_string()),
            num(fl.and_then(|l| r.level(l)), 4),
            fl.map_or("—".into(), |l| l.to_string()),
            num(r.ratio(), 3),
            match (r.trimmed_ratio(), r.trimmed_best()) {
                (Some(x), Some(b)) => format!("{x:.3}× ({})", b.level),
                _ => "—".into(),
            },
            num(r.alphasurf_f1, 3),
            num(r.best_f1, 3),
            r.stage1_psnr,
            num(r.stage2_psnr, 2),
            r.wall_s,
        );
    }
    for c in &s.categories {
        t += &format!(
            "| **mean** ({} scene{}) | {} | {} | {} | {} ({}) | {}× | {} | | {:.2} → {} dB | |\n",
            c.scenes,
            if c.scenes == 1 { "" } else { "s" },
            c.category,
            num(c.alphasurf_chamfer_e2, 4),
            num(c.best_chamfer_e2, 4),
            num(c.fixed_level_chamfer_e2, 4),
            c.fixed_level.map_or("—".into(), |l| l.to_string()),
            num(c.ratio, 3),
            c.trimmed_ratio.map_or("—".into(), |x| format!("{x:.3}×")),
            c.stage1_psnr,
            num(c.stage2_psnr, 2),
        );
    }
    t
}

/// A stored result for these settings, if there is one and it did not fail (a failed scene, e.g.
/// a full disk, is computed again from its finished stage 1).
fn stored(path: &Path, settings: &Settings) -> Result<Option<SceneResult>> {
    if !path.exists() {
        return Ok(None);
    }
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let r: SceneResult =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
    if &r.settings != settings {
        eprintln!(
            "  {} holds a result for other settings: computing it again",
            path.display()
        );
        return Ok(None);
    }
    if let Some(e) = &r.error {
        eprintln!(
            "  {} failed before ({e}): computing it again",
            path.display()
        );
        return Ok(None);
    }
    Ok(Some(r))
}

/// This build's configurations for a scene's two runs, from its settings.
struct Expected {
    stage1: PlenoxelsConfig,
    stage2: SurfaceConfig,
}

impl Expected {
    fn new(steps: &Steps, args: &AccuracyArgs, settings: &Settings) -> Result<Expected> {
        let s = &settings.stage1;
        let mut stage1 = steps.plenoxels_config(&s.data, &s.overrides())?;
        stage1.seed = s.seed;
        let grid_n = stage1.res_at(stage1.iters);
        let stage2 = steps.surface_config(&s.data, &stage2_overrides(args, settings), grid_n)?;
        Ok(Expected { stage1, stage2 })
    }
}

/// How the configuration recorded in the run at `dir` (its metrics.json's `config`) differs
/// from `here`: the first field that differs, as "field: THERE there, HERE here"; `None` when
/// they are the same. A run whose configuration cannot be read differs. The record is read as
/// `C` first, so that its numbers compare at the precision they were written from.
fn config_difference<C: Serialize + DeserializeOwned>(dir: &Path, here: &C) -> Option<String> {
    let there = metrics::read::<serde_json::Value>(dir)
        .and_then(|mut m| Ok(serde_json::from_value::<C>(m["config"].take())?));
    let both = there.and_then(|c| Ok((serde_json::to_value(c)?, serde_json::to_value(here)?)));
    let (there, here) = match both {
        Ok(both) => both,
        Err(e) => return Some(format!("{e:#}")),
    };
    let (k, _) = (here.as_object().into_iter())
        .chain(there.as_object())
        .flatten()
        .find(|(k, _)| there.get(*k) != here.get(*k))?;
    let show = |v: &serde_json::Value| v.get(k).map_or("absent".into(), |x| x.to_string());
    Some(format!("{k}: {} there, {} here", show(&there), show(&here)))
}

/// Write `value` as pretty JSON, atomically.
fn write_json(path: &Path, value: &impl Serialize) -> Result<()> {
    crate::io::atomic::write_bytes(path, serde_json::to_string_pretty(value)?.as_bytes())
}

/// The stage-1 record in `dir`, if its run finished.
fn read_plenoxels(dir: &Path) -> Result<Option<PlenoxelsRecord>> {
    let rec = dir.join("stage1.json");
    if !(dir.join(crate::run::dir::METRICS).is_file() && rec.is_file()) {
        return Ok(None);
    }
    let text =
        std::fs::read_to_string(&rec).with_context(|| format!("reading {}", rec.display()))?;
    serde_json::from_str(&text)
        .with_context(|| format!("parsing {}", rec.display()))
        .map(Some)
}

/// Stage 1 of a scene and its level sweep in `dir`: reused when it finished with `settings`,
/// else trained and swept.
fn stage1(
    steps: &Steps,
    settings: &PlenoxelsSettings,
    config: &PlenoxelsConfig,
    dir: &Path,
) -> Result<(TrainedRun, PlenoxelsRecord)> {
    if let Some(r) = read_plenoxels(dir)?.filter(|r| &r.settings == settings) {
        match config_difference(dir, config) {
            None => {
                eprintln!("  stage 1: reusing {}", dir.display());
                return Ok((TrainedRun::read_plenoxels(dir, r.wall_s)?, r));
            }
            Some(d) => eprintln!(
                "  stage 1 in {} was trained with another configuration than this build's \
                 ({d}): training it again",
                dir.display()
            ),
        }
    }
    // An unfinished or outdated run there is replaced (`train --overwrite`).
    let run = steps.train_plenoxels(&settings.data, dir, &settings.overrides())?;
    let gt = settings.data.join("gt_points.ply");
    let t = Instant::now();
    let rows = plenoxels_levels(steps, &run, &gt, &LEVELS);
    let rec = PlenoxelsRecord {
        settings: settings.clone(),
        wall_s: run.wall_s,
        levels: LEVELS.iter().map(|&l| score(&rows, l)).collect(),
        levels_s: t.elapsed().as_secs_f64(),
    };
    write_json(&dir.join("stage1.json"), &rec)?;
    Ok((run, rec))
}

fn score(rows: &[Row], level: f32) -> LevelScore {
    let r = rows.iter().find(|r| r.level == Some(level));
    LevelScore {
        level,
        chamfer_e2: r.and_then(|r| r.chamfer_e2),
        f1: r.and_then(|r| r.f1),
    }
}

/// Where a scene's stage-1 run lives: under `--stage1-from` or this output.
fn stage1_dir(args: &AccuracyArgs, out: &Path) -> PathBuf {
    match &args.stage1_from {
        Some(from) => from
            .join(out.file_name().unwrap_or_default())
            .join("plenoxels"),
        None => out.join("plenoxels"),
    }
}

/// Stage 2's `--set` list: `--batch`, then `--surface-set` (applied in order, so
/// `--surface-set batch=N` gives stage 2 its own batch).
fn surface_overrides(args: &AccuracyArgs) -> Vec<String> {
    let batch = args.batch.map(|b| format!("batch={b}"));
    batch
        .into_iter()
        .chain(args.surface_set.iter().cloned())
        .collect()
}

/// What stage 2 of a scene is trained with.
fn stage2_overrides(args: &AccuracyArgs, settings: &Settings) -> SurfaceOverrides {
    SurfaceOverrides {
        category: settings.category,
        iters: settings.surface_iters,
        set: surface_overrides(args),
    }
}

/// One scene, end to end.
fn scene(
    steps: &Steps,
    args: &AccuracyArgs,
    out: &Path,
    settings: Settings,
    expected: &Expected,
) -> Result<SceneResult> {
    let t0 = Instant::now();
    let data = &settings.stage1.data;
    let gt = data.join("gt_points.ply");
    ensure!(
        gt.is_file(),
        "{}: no gt_points.ply (bench accuracy needs ground truth)",
        data.display()
    );
    let (s1, rec) = stage1(
        steps,
        &settings.stage1,
        &expected.stage1,
        &stage1_dir(args, out),
    )?;
    let best = rec.best();
    // The like-for-like baseline where αSurf's extraction trims hidden cells and centres thin
    // sheets (thin).
    let t = Instant::now();
    let trimmed_levels = if settings.category == Category::Thin {
        let rows = plenoxels_levels_trimmed(steps, &s1, &gt, &LEVELS, out);
        LEVELS.iter().map(|&l| score(&rows, l)).collect()
    } else {
        Vec::new()
    };
    let trimmed_levels_s = t.elapsed().as_secs_f64();
    // A stage-2 run without result.json was interrupted: `train --overwrite` starts it again.
    let s2_dir = out.join("alphasurf");
    // A failed stage 2 is the scene's result; a stop asked for by a signal ends the bench.
    let s2 = interrupt::unless_stopped(steps.train_surface(
        &s1.dir,
        data,
        &s2_dir,
        &stage2_overrides(args, &settings),
    ))?;
    let t = Instant::now();
    let (surf, s2_wall, error) = match &s2 {
        Ok(s2) => {
            let r = alphasurf_row(steps, &s1, s2, &gt);
            let e = r.error.clone();
            (Some(r), s2.wall_s, e)
        }
        Err(e) => (None, 0.0, Some(format!("{e:#}"))),
    };
    let time = SceneTime {
        stage1: metrics::read::<PlenoxelsMetrics>(&s1.dir)
            .ok()
            .map(|m| m.wall_seconds),
        levels_s: rec.levels_s,
        trimmed_levels_s,
        stage2: s2
            .as_ref()
            .ok()
            .and_then(|r| metrics::read::<SurfaceMetrics>(&r.dir).ok())
            .map(|m| m.wall_seconds),
        alphasurf_score_s: t.elapsed().as_secs_f64(),
    };
    Ok(SceneResult {
        scene: scene_name(data),
        best_level: best.map(|b| b.level),
        best_chamfer_e2: best.and_then(|b| b.chamfer_e2),
        best_f1: best.and_then(|b| b.f1),
        levels: rec.levels,
        trimmed_levels,
        alphasurf_chamfer_e2: surf.as_ref().and_then(|r| r.chamfer_e2),
        alphasurf_f1: surf.as_ref().and_then(|r| r.f1),
        stage1_psnr: s1.test_psnr,
        stage2_psnr: s2.as_ref().ok().map(|r| r.test_psnr),
        train_wall_s: s1.wall_s + s2_wall,
        wall_s: t0.elapsed().as_secs_f64(),
        error,
        time: Some(time),
        settings,
    })
}

/// Run `bench accuracy`.
pub fn run(args: &AccuracyArgs, devices: &mut Devices) -> Result<()> {
    let steps = Steps {
        preset: args.preset,
        seed: args.seed,
        space: args.space,
        background: args.background,
        ..Steps::new(devices.for_backend(args.backend)?)
    };
    let out = args.out.clone().unwrap_or_else(|| {
        PathBuf::from(format!(
            "runs/accuracy-{}-{}-s{}",
            args.res.map_or("preset".into(), |r| r.to_string()),
            args.preset,
            args.seed
        ))
    });
    let todo = scenes_to_run(args)?;
    let mut results = Vec::new();
    for (i, sc) in todo.into_iter().enumerate() {
        let name = sc.name.clone();
        let dir = out.join(&name);
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        let (settings, expected) = scene_settings(&steps, args, &dir, sc)?;
        let path = dir.join("result.json");
        eprintln!(
            "\n=== bench accuracy [{}/{}] {name} ({}) → {}",
            i + 1,
            args.data.len(),
            settings.category,
            dir.display()
        );
        let r = match stored_for_this_build(args, &dir, &path, &settings, &expected)? {
            Some(r) => {
                eprintln!("  finished before: {}", path.display());
                r
            }
            None => {
                let r = scene(&steps, args, &dir, settings, &expected)?;
                write_json(&path, &r)?;
                r
            }
        };
        print_scene_summary(&r);
        results.push(r);
    }
    let failed = results
        .iter()
        .filter(|r| r.alphasurf_chamfer_e2.is_none() && r.best_chamfer_e2.is_none())
        .count();
    let scenes = results.len();
    let summary = summarise(results);
    write_json(&out.join("accuracy.json"), &summary)?;
    println!("\n{}", table(&summary));
    println!("Chamfer ×10⁻²; ratio = αSurf / the scene's best Plenoxels level.");
    if args.json {
        println!("{}", serde_json::to_string(&summary)?);
    }
    super::ensure_any_succeeded("scene's evaluation", failed, scenes)
}

/// Each `--data` folder with its name and category, checked before the first scene trains so
/// that a bad folder or a name clash fails at once.
fn scenes_to_run(args: &AccuracyArgs) -> Result<Vec<Scene>> {
    let mut todo: Vec<Scene> = Vec::new();
    for d in &args.data {
        ensure!(d.is_dir(), "{}: not a directory", d.display());
        let name = scene_name(d);
        ensure!(
            todo.iter().all(|s| s.name != name),
            "two scenes are named {name:?}: their folders would collide under --out"
        );
        // Where the scene trains and on what, as `train` decides (`--space`, `--background`);
        // a folder whose category its name cannot tell is refused before it is read.
        let load = || {
            let opts = LoadOptions {
                background: args.background,
                space: args.space,
                ..Default::default()
            };
            Dataset::load(d, &opts)
        };
        let mut loaded = None;
        let category = scene_category(d, args.category, || {
            let data = load()?;
            let ndc = data.scene.ndc.is_some();
            loaded = Some(data);
            Ok(ndc)
        })?;
        let data = match loaded {
            Some(data) => data,
            None => load()?,
        };
        todo.push(Scene {
            category,
            background: data.background,
            data: d.clone(),
            name,
        });
    }
    Ok(todo)
}

/// A scene to run: its folder, name, category and background (`--background` resolved).
struct Scene {
    data: PathBuf,
    name: String,
    category: Category,
    background: BackgroundMode,
}

/// A scene's settings and this build's configurations for them. With `--stage1-from`, the
/// other output's stage-1 run is checked to match (its seed is taken over) and refused when
/// this build would configure it otherwise.
fn scene_settings(
    steps: &Steps,
    args: &AccuracyArgs,
    dir: &Path,
    scene: Scene,
) -> Result<(Settings, Expected)> {
    let category = scene.category;
    let mut stage1 = PlenoxelsSettings {
        data: scene.data,
        res: args.res,
        iters: args.iters,
        batch: args.batch,
        preset: args.preset,
        seed: args.seed,
        backend: steps.backend(),
        set: args.plenoxels_set.clone(),
        space: args.space,
        background: scene.background,
    };
    if args.stage1_from.is_some() {
        // Another output's stage 1, whatever its seed, as long as the rest matches.
        let from = stage1_dir(args, dir);
        let rec = read_plenoxels(&from)?.with_context(|| {
            format!(
                "--stage1-from: {} holds no finished stage-1 run",
                from.display()
            )
        })?;
        stage1.seed = rec.settings.seed;
        ensure!(
            rec.settings == stage1,
            "--stage1-from: {} was trained with other settings ({:?}, here {:?})",
            from.display(),
            rec.settings,
            stage1
        );
    }
    let settings = Settings {
        stage1,
        category,
        seed: args.seed,
        surface_iters: args.surface_iters,
        surface_set: args.surface_set.clone(),
    };
    let expected = Expected::new(steps, args, &settings)?;
    if args.stage1_from.is_some() {
        let from = stage1_dir(args, dir);
        if let Some(d) = config_difference(&from, &expected.stage1) {
            bail!(
                "--stage1-from: {} was trained with another stage-1 configuration than this \
                 build's ({d}), e.g. by a build with other presets; train stage 1 again \
                 (leave out --stage1-from)",
                from.display()
            );
        }
    }
    Ok((settings, expected))
}

/// The stored result at `path` when it is for these settings and both of its runs had the
/// configuration this build gives them (an older build's result is computed again).
fn stored_for_this_build(
    args: &AccuracyArgs,
    dir: &Path,
    path: &Path,
    settings: &Settings,
    expected: &Expected,
) -> Result<Option<SceneResult>> {
    Ok(stored(path, settings)?.filter(|_| {
        let differs = [
            (
                "stage-1",
                config_difference(&stage1_dir(args, dir), &expected.stage1),
            ),
            (
                "stage-2",
                config_difference(&dir.join("alphasurf"), &expected.stage2),
            ),
        ];
        let differs = differs.into_iter().find_map(|(s, d)| Some((s, d?)));
        if let Some((stage, d)) = &differs {
            eprintln!(
                "  {} holds a result whose {stage} run had another configuration than this \
                 build's ({d}): computing it again",
                path.display()
            );
        }
        differs.is_none()
    }))
}

/// A scene's headline figures and time breakdown on stderr.
fn print_scene_summary(r: &SceneResult) {
    eprintln!(
        "  αSurf {} vs best Plen {} (σ = {}), PSNR {:.2} → {} dB",
        num(r.alphasurf_chamfer_e2, 4),
        num(r.best_chamfer_e2, 4),
        r.best_level.map_or("—".into(), |l| l.to_string()),
        r.stage1_psnr,
        num(r.stage2_psnr, 2)
    );
    if let Some(t) = &r.time {
        eprintln!("  time: {}", t.line());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_written_before_the_time_breakdown_still_read() {
        let mut r = result("thin_fan", Category::Thin, &[(50.0, 0.5)], 0.35);
        let mut v = serde_json::to_value(&r).unwrap();
        v.as_object_mut().unwrap().remove("time");
        let back: SceneResult = serde_json::from_value(v).unwrap();
        assert!(back.time.is_none());
        let rec = r#"{"settings":{"data":"d","res":256,"iters":null,"batch":null,
            "preset":"fast","seed":0,"backend":"cpu"},"wall_s":130.7,"levels":[]}"#;
        let rec: PlenoxelsRecord = serde_json::from_str(rec).unwrap();
        assert_eq!(rec.levels_s, 0.0);
        r.time = Some(SceneTime {
            stage1: None,
            levels_s: 12.31,
            trimmed_levels_s: 3.5,
            stage2: None,
            alphasurf_score_s: 4.0,
        });
        let line = r.time.as_ref().unwrap().line();
        assert!(line.contains("level sweep 12.3 s, trimmed 3.5 s"), "{line}");
        assert!(line.contains("αSurf extract + eval 4.0 s"), "{line}");
    }

    #[test]
    fn a_failed_scene_is_computed_again_a_finished_one_is_not() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("result.json");
        let mut r = result("thin_fan", Category::Thin, &[(50.0, 0.5)], 0.35);
        write_json(&path, &r).unwrap();
        assert!(stored(&path, &r.settings).unwrap().is_some());
        let mut other = r.settings.clone();
        other.seed = 1;
        assert!(stored(&path, &other).unwrap().is_none());
        r.error = Some("writing surface.npz: No space left on device".into());
        write_json(&path, &r).unwrap();
        assert!(stored(&path, &r.settings).unwrap().is_none());
    }

    #[test]
    fn a_stage_2_batch_overrides_the_shared_one() {
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            args: AccuracyArgs,
        }
        let parse = |extra: &[&str]| {
            let base = ["bench", "--data", "d"];
            let cli: Cli = clap::Parser::parse_from(base.iter().chain(extra));
            surface_overrides(&cli.args)
        };
        assert!(parse(&[]).is_empty());
        assert_eq!(parse(&["--batch", "16384"]), ["batch=16384"]);
        assert_eq!(
            parse(&["--batch", "16384", "--surface-set", "batch=4096"]),
            ["batch=16384", "batch=4096"]
        );
    }

    fn result(scene: &str, category: Category, levels: &[(f32, f64)], surf: f64) -> SceneResult {
        let best = levels.iter().min_by(|a, b| a.1.total_cmp(&b.1)).unwrap();
        SceneResult {
            scene: scene.into(),
            settings: Settings {
                stage1: PlenoxelsSettings {
                    data: scene.into(),
                    res: Some(64),
                    iters: None,
                    batch: None,
                    preset: Preset::Fast,
                    seed: 0,
                    backend: Backend::Cpu,
                    set: vec![],
                    space: Space::Auto,
                    background: BackgroundMode::White,
                },
                category,
                seed: 0,
                surface_iters: None,
                surface_set: vec![],
            },
            levels: levels
                .iter()
                .map(|&(level, c)| LevelScore {
                    level,
                    chamfer_e2: Some(c),
                    f1: Some(0.5),
                })
                .collect(),
            trimmed_levels: Vec::new(),
            best_level: Some(best.0),
            best_chamfer_e2: Some(best.1),
            best_f1: Some(0.5),
            alphasurf_chamfer_e2: Some(surf),
            alphasurf_f1: Some(0.6),
            stage1_psnr: 30.0,
            stage2_psnr: Some(28.0),
            train_wall_s: 1.0,
            wall_s: 2.0,
            error: None,
            time: None,
        }
    }

    #[test]
    fn categories_come_from_folder_names_or_the_flag() {
        let c = |p: &str, g: Option<Category>| scene_category(Path::new(p), g, || Ok(true));
        assert_eq!(c("fixtures/thin_lyre", None).unwrap(), Category::Thin);
        assert_eq!(
            c("x/translucent_lampshade/", None).unwrap(),
            Category::Translucent
        );
        assert_eq!(c("x/lyre", Some(Category::Thin)).unwrap(), Category::Thin);
        let e = c("x/lyre", None).unwrap_err().to_string();
        assert!(e.contains("x/lyre") && e.contains("--category"), "{e}");
        assert!(c("x/thinner_lyre", None).is_err());
        assert_eq!(c("x/capture_fan_ff", None).unwrap(), Category::Real);
        // A capture in a box (360°, on background spheres): translucent.
        let boxed = scene_category(Path::new("x/capture_birdcage"), None, || Ok(false));
        assert_eq!(boxed.unwrap(), Category::Translucent);
        assert_eq!(
            c("x/capture_fan_ff", Some(Category::Thin)).unwrap(),
            Category::Thin
        );
    }

    #[test]
    fn fixed_level_is_the_best_mean_of_the_category() {
        // Scene a is best at 30, scene b at 50; the mean is best at 50 (0.9 vs 1.0).
        let a = result("a", Category::Thin, &[(30.0, 0.5), (50.0, 0.6)], 0.4);
        let b = result("b", Category::Thin, &[(30.0, 1.5), (50.0, 1.2)], 1.5);
        let t = result("t", Category::Translucent, &[(10.0, 2.0), (30.0, 3.0)], 1.0);
        let s = summarise(vec![a, b, t]);
        let thin = &s.categories[0];
        assert_eq!((thin.category, thin.scenes), (Category::Thin, 2));
        assert_eq!(thin.fixed_level, Some(50.0));
        assert!((thin.fixed_level_chamfer_e2.unwrap() - 0.9).abs() < 1e-12);
        assert!((thin.best_chamfer_e2.unwrap() - 0.85).abs() < 1e-12);
        // Ratios 0.8 and 1.25: the mean of the per-scene ratios.
        assert!((thin.ratio.unwrap() - 1.025).abs() < 1e-12);
        assert_eq!(s.categories[1].fixed_level, Some(10.0));
        let t = table(&s);
        assert_eq!(t.lines().count(), 2 + 3 + 2, "{t}");
        assert!(
            t.contains("| a | thin | 0.4000 | 0.5000 (30) | 0.6000 (50) | 0.800× |"),
            "{t}"
        );
        assert!(
            t.contains("| b | thin | 1.5000 | 1.2000 (50) | 1.2000 (50) | 1.250× |"),
            "{t}"
        );
    }

    #[test]
    fn the_trimmed_levels_give_the_like_for_like_ratio() {
        let mut a = result("a", Category::Thin, &[(30.0, 0.5), (50.0, 0.6)], 0.4);
        a.trimmed_levels = [(30.0, 0.45), (50.0, 0.8)]
            .iter()
            .map(|&(level, c)| LevelScore {
                level,
                chamfer_e2: Some(c),
                f1: None,
            })
            .collect();
        assert_eq!(a.trimmed_best().map(|b| b.level), Some(30.0));
        assert!((a.trimmed_ratio().unwrap() - 0.4 / 0.45).abs() < 1e-12);
        let b = result("b", Category::Thin, &[(30.0, 1.0)], 0.5);
        let s = summarise(vec![a.clone(), b]);
        // One scene without a trimmed sweep: no mean.
        assert_eq!(s.categories[0].trimmed_ratio, None);
        let t = table(&s);
        assert!(t.contains("| 0.800× | 0.889× (30) |"), "{t}");
        assert!(t.contains("| 0.500× | — |"), "{t}");
        let s = summarise(vec![a]);
        assert!((s.categories[0].trimmed_ratio.unwrap() - 0.4 / 0.45).abs() < 1e-12);
    }

    #[test]
    fn a_missing_figure_leaves_the_mean_empty() {
        let mut a = result("a", Category::Thin, &[(30.0, 0.5)], 0.4);
        a.alphasurf_chamfer_e2 = None;
        let s = summarise(vec![a, result("b", Category::Thin, &[(30.0, 0.7)], 0.6)]);
        assert_eq!(s.categories[0].alphasurf_chamfer_e2, None);
        assert_eq!(s.categories[0].ratio, None);
        assert!(table(&s).contains("| a | thin | — |"));
    }
}
