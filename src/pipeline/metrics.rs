//! A training run's `metrics.json`, typed: [`TrainMetrics`], what both stages record, with
//! [`PlenoxelsMetrics`] for a stage-1 (Plenoxels) run and [`SurfaceMetrics`] for a stage-2
//! (αSurf) run. The JSON layout is the one runs have always written; counters added over time
//! are `Option`s, absent in runs written before them.

use crate::checkpoint::BackgroundRecord;
use crate::run::dir::METRICS;
use crate::train::{PlenoxelsConfig, SurfaceConfig};
use anyhow::{Context, Result};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Wall time of a stage-1 run's phases, seconds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlenoxelsSeconds {
    /// Reading the dataset.
    pub load: f64,
    pub train: f64,
    pub upsample: f64,
    pub checkpoint: f64,
    pub render_test: f64,
    /// The whole command.
    pub total: f64,
}

impl PlenoxelsSeconds {
    /// A run's wall time `s` with the upsamplings' `upsample` seconds.
    pub fn with_upsample(s: SurfaceSeconds, upsample: f64) -> Self {
        PlenoxelsSeconds {
            load: s.load,
            train: s.train,
            upsample,
            checkpoint: s.checkpoint,
            render_test: s.render_test,
            total: s.total,
        }
    }
}

/// Samples per training ray of stage 1.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SamplesPerRay {
    /// Shaded (σ above the threshold).
    pub shaded: f64,
    /// Evaluated and found empty.
    pub empty: f64,
    /// Skipped by the occupancy volume.
    pub skipped: f64,
}

/// `metrics.json` of a training run: what both stages record, with the stage's wall time per
/// phase `W`, its own figures `X` (their fields stand between the test PSNR and the peak memory,
/// as runs have always written them) and its configuration `C`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainMetrics<W, X, C> {
    /// "plenoxels" or "surface".
    pub stage: String,
    /// The backend's name ("cpu", "vulkan").
    pub backend: String,
    /// The Vulkan device's name (`None` on the CPU backend).
    #[serde(default)]
    pub device: Option<String>,
    pub wall_seconds: W,
    pub train_rays_per_s: f64,
    pub final_train_mse: f64,
    /// Mean PSNR over the test views, dB.
    pub test_psnr: f64,
    pub test_psnr_per_view: Vec<f64>,
    #[serde(flatten)]
    pub figures: X,
    /// Peak resident memory of the process (where the platform reports it).
    pub peak_rss_bytes: Option<u64>,
    /// The background at the end (a learned colour's value; absent in older runs: white).
    #[serde(default)]
    pub background: BackgroundRecord,
    pub config: C,
}

/// `metrics.json` of a stage-1 run.
pub type PlenoxelsMetrics = TrainMetrics<PlenoxelsSeconds, PlenoxelsFigures, PlenoxelsConfig>;

/// What a stage-1 run records besides [`TrainMetrics`]' shared fields.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlenoxelsFigures {
    pub samples_per_ray: Option<SamplesPerRay>,
    pub atomic_adds_per_ray: Option<f64>,
    pub allocated_vertices: usize,
    /// Bytes per vertex with its optimiser state.
    pub bytes_per_vertex: f64,
}

/// Wall time of a stage-2 run's phases, seconds (of a stage-1 run: all but the upsamplings').
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SurfaceSeconds {
    /// Reading the dataset.
    pub load: f64,
    pub train: f64,
    pub checkpoint: f64,
    pub render_test: f64,
    /// The whole command.
    pub total: f64,
}

/// Per training ray of stage 2 (the kernel's counters over the run's steps).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SurfacePerRay {
    /// Cells read (live cells).
    pub cells: f64,
    /// Cubic solves.
    pub solves: f64,
    /// Solves skipped by the min/max test or segment culling.
    pub culled_solves: f64,
    pub hits: f64,
    /// Hits cut by the truncation.
    pub cut_hits: f64,
    /// Hits whose δ gradient was guarded.
    pub guarded_hits: f64,
    /// Gradient atomic adds.
    pub atomic_adds: f64,
    /// Empty-space blocks skipped.
    pub blocks_skipped: Option<f64>,
}

/// `metrics.json` of a stage-2 run.
pub type SurfaceMetrics = TrainMetrics<SurfaceSeconds, SurfaceFigures, SurfaceConfig>;

/// What a stage-2 run records besides [`TrainMetrics`]' shared fields.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SurfaceFigures {
    pub per_ray: Option<SurfacePerRay>,
    /// Vertices before dropping the surfaces with α below the configuration's `prune_alpha`.
    pub vertices_before_prune: Option<usize>,
    pub allocated_vertices: usize,
}

/// Read the `metrics.json` of the run in `dir`.
pub fn read<M: DeserializeOwned>(dir: &Path) -> Result<M> {
    let path = dir.join(METRICS);
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))
}

impl PlenoxelsMetrics {
    /// The lines `train` prints when stage 1 ends: per-view PSNR, per-ray counters, the summary.
    pub fn summary(&self) -> String {
        let mut s = views(&self.test_psnr_per_view);
        let f = &self.figures;
        if let (Some(spr), Some(adds)) = (&f.samples_per_ray, f.atomic_adds_per_ray) {
            s += &format!(
                "per training ray: {:.1} samples shaded, {:.1} evaluated empty, {:.1} skipped by \
                 the occupancy volume; {:.1} gradient atomic adds\n",
                spr.shaded, spr.empty, spr.skipped, adds
            );
        }
        s + &format!(
            "stage 1 done: test PSNR {:.2} dB, {:.0} training rays/s, {} vertices ({:.0} B each \
             with optimiser state), {:.1} s\n",
            self.test_psnr,
            self.train_rays_per_s,
            f.allocated_vertices,
            f.bytes_per_vertex,
            self.wall_seconds.total
        )
    }
}

impl SurfaceMetrics {
    /// The lines `train` prints when stage 2 ends: per-view PSNR, per-ray counters, the summary.
    pub fn summary(&self) -> String {
        let mut s = views(&self.test_psnr_per_view);
        let f = &self.figures;
        if let Some(r) = &f.per_ray {
            s += &format!(
                "per training ray: {:.1} cells read ({:.1} empty blocks skipped), {:.2} cubic \
                 solves ({:.1} skipped by min/max or segment culling), {:.2} hits, {:.2} cut by \
                 truncation, {:.3} guarded, {:.1} gradient atomic adds\n",
                r.cells,
                r.blocks_skipped.unwrap_or(0.0),
                r.solves,
                r.culled_solves,
                r.hits,
                r.cut_hits,
                r.guarded_hits,
                r.atomic_adds
            );
        }
        s + &format!(
            "stage 2 done: test PSNR {:.2} dB, {:.0} training rays/s, {} vertices after dropping \
             α < {} ({} before), {:.1} s\n",
            self.test_psnr,
            self.train_rays_per_s,
            f.allocated_vertices,
            self.config.prune_alpha,
            f.vertices_before_prune
                .map_or("?".to_string(), |n| n.to_string()),
            self.wall_seconds.total
        )
    }
}

/// One line per test view.
fn views(psnr: &[f64]) -> String {
    psnr.iter()
        .enumerate()
        .map(|(i, p)| format!("test view {i:>3}: PSNR {p:.2} dB\n"))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::{Category, Preset};
    use serde_json::{json, Value};

    /// metrics.json of a stage-1 run as the untyped writer wrote it (before these types).
    fn stage1_untyped() -> Value {
        json!({
            "stage": "plenoxels",
            "backend": "cpu",
            "device": null,
            "wall_seconds": {
                "load": 0.5, "train": 10.0, "upsample": 1.0, "checkpoint": 0.25,
                "render_test": 2.0, "total": 14.0,
            },
            "train_rays_per_s": 150000.0,
            "final_train_mse": 0.004,
            "test_psnr": 21.9,
            "test_psnr_per_view": [21.5, 22.3],
            "samples_per_ray": { "shaded": 5.5, "empty": 20.25, "skipped": 100.0 },
            "atomic_adds_per_ray": 88.0,
            "allocated_vertices": 12345,
            "bytes_per_vertex": 224.0,
            "peak_rss_bytes": 1048576,
            "config": PlenoxelsConfig::fast(),
        })
    }

    /// metrics.json of a stage-2 run as the untyped writer wrote it.
    fn stage2_untyped() -> Value {
        json!({
            "stage": "surface",
            "backend": "vulkan",
            "device": "llvmpipe",
            "wall_seconds": {
                "load": 0.5, "train": 10.0, "checkpoint": 0.25, "render_test": 2.0,
                "total": 13.0,
            },
            "train_rays_per_s": 90000.0,
            "final_train_mse": 0.005,
            "test_psnr": 21.2,
            "test_psnr_per_view": [21.0],
            "per_ray": {
                "cells": 30.0, "solves": 4.5, "culled_solves": 20.0, "hits": 1.5,
                "cut_hits": 0.25, "guarded_hits": 0.0, "atomic_adds": 60.0, "blocks_skipped": 3.0,
            },
            "vertices_before_prune": 9000,
            "allocated_vertices": 8752,
            "peak_rss_bytes": null,
            "config": SurfaceConfig::preset(Preset::Fast, Category::Thin).unwrap(),
        })
    }

    /// `v` as the typed metrics write it back: with the background the untyped writer did not
    /// record (its runs trained on white).
    fn with_white_background(mut v: Value) -> Value {
        v["background"] =
            json!({ "mode": "white", "rgb": [1.0, 1.0, 1.0], "avg": [0.0, 0.0, 0.0] });
        v
    }

    #[test]
    fn the_typed_metrics_read_and_write_the_untyped_layout() {
        let v = stage1_untyped();
        let m: PlenoxelsMetrics = serde_json::from_value(v.clone()).unwrap();
        assert_eq!(m.figures.samples_per_ray.as_ref().unwrap().empty, 20.25);
        assert_eq!(serde_json::to_value(&m).unwrap(), with_white_background(v));
        let v = stage2_untyped();
        let m: SurfaceMetrics = serde_json::from_value(v.clone()).unwrap();
        assert_eq!(
            m.figures.per_ray.as_ref().unwrap().blocks_skipped,
            Some(3.0)
        );
        assert_eq!(serde_json::to_value(&m).unwrap(), with_white_background(v));
    }

    #[test]
    fn runs_written_before_the_later_counters_still_load() {
        let mut v = stage1_untyped();
        for k in [
            "device",
            "samples_per_ray",
            "atomic_adds_per_ray",
            "peak_rss_bytes",
        ] {
            v.as_object_mut().unwrap().remove(k);
        }
        let m: PlenoxelsMetrics = serde_json::from_value(v).unwrap();
        assert_eq!((&m.device, m.figures.atomic_adds_per_ray), (&None, None));
        assert!(m.summary().contains("stage 1 done: test PSNR 21.90 dB"));
        assert!(!m.summary().contains("per training ray"));
        let mut v = stage2_untyped();
        for k in [
            "device",
            "per_ray",
            "vertices_before_prune",
            "peak_rss_bytes",
        ] {
            v.as_object_mut().unwrap().remove(k);
        }
        let m: SurfaceMetrics = serde_json::from_value(v).unwrap();
        let f = m.figures;
        assert_eq!((f.per_ray, f.vertices_before_prune), (None, None));
        let mut v = stage2_untyped();
        v["per_ray"]
            .as_object_mut()
            .unwrap()
            .remove("blocks_skipped");
        let m: SurfaceMetrics = serde_json::from_value(v).unwrap();
        assert_eq!(m.figures.per_ray.unwrap().blocks_skipped, None);
        // A stage-2 file is not a stage-1 run's metrics.
        assert!(serde_json::from_value::<PlenoxelsMetrics>(stage2_untyped()).is_err());
    }

    #[test]
    fn read_names_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let e = format!("{:#}", read::<PlenoxelsMetrics>(dir.path()).unwrap_err());
        assert!(e.contains(METRICS), "{e}");
        std::fs::write(dir.path().join(METRICS), "{}").unwrap();
        let e = format!("{:#}", read::<PlenoxelsMetrics>(dir.path()).unwrap_err());
        assert!(e.contains("parsing") && e.contains(METRICS), "{e}");
    }
}
