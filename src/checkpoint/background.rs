//! A run's background as its checkpoints and metrics record it: the mode, the colour and, when
//! it is learned, the optimiser's running average; carried from stage 1 into stage 2.

use crate::abi::buffers::Background;
use crate::data::{BackgroundMode, Dataset};
use anyhow::{ensure, Context, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Key of the record in a checkpoint's metadata.
pub const META_KEY: &str = "background";

/// The background of a run at a step (default: white, of runs that did not record one).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct BackgroundRecord {
    pub mode: BackgroundMode,
    /// The colour composited behind every ray.
    pub rgb: [f32; 3],
    /// RMSProp running average of a learned colour's gradient (zero when fixed).
    pub avg: [f32; 3],
}

impl Default for BackgroundRecord {
    fn default() -> Self {
        Self::start(BackgroundMode::White)
    }
}

impl BackgroundRecord {
    /// A background of `mode` at its colour at load (`BackgroundMode::initial_rgb`).
    pub fn start(mode: BackgroundMode) -> Self {
        BackgroundRecord {
            mode,
            rgb: mode.initial_rgb(),
            avg: [0.0; 3],
        }
    }

    /// A run's background before its first step on `data`: its mode's colour, or, learned, the
    /// median colour of the training images' borders. Starting a learned colour far from the
    /// backdrop (at grey) lets the grid explain the difference with coloured fog in empty space
    /// first, which the colour, once it has converged, does not clear (docs/results.md,
    /// "Learned background").
    pub fn start_on(data: &Dataset) -> Self {
        let mut r = Self::start(data.background);
        if data.background.learned() {
            r.rgb = data.train.border_median();
        }
        r
    }

    /// What a backend holds, of a run in `mode`.
    pub fn of(mode: BackgroundMode, bg: &Background) -> Self {
        BackgroundRecord {
            mode,
            rgb: bg.rgb,
            avg: bg.avg,
        }
    }

    /// The kernels' background (no gradient pending).
    pub fn kernel(&self) -> Background {
        Background {
            avg: self.avg,
            ..Background::new(self.rgb, self.mode.learned())
        }
    }

    /// The record in the metadata of the checkpoint at `path`; a checkpoint without one (written
    /// before backgrounds were recorded) trained on white.
    pub fn from_meta(meta: &serde_json::Value, path: &Path) -> Result<Self> {
        let Some(v) = meta.get(META_KEY) else {
            return Ok(Self::start(BackgroundMode::White));
        };
        let r: Self = serde_json::from_value(v.clone())
            .with_context(|| format!("{}: metadata '{META_KEY}' is invalid", path.display()))?;
        ensure!(
            r.rgb.iter().chain(&r.avg).all(|x| x.is_finite()),
            "{}: metadata '{META_KEY}' has a non-finite value: {r:?}",
            path.display()
        );
        Ok(r)
    }

    /// Refuse a run whose `--background` differs from this record's (`what` names the record's
    /// source): the images were composited, and the grid trained, on this one.
    pub fn ensure_mode(&self, asked: BackgroundMode, what: &str) -> Result<()> {
        ensure!(
            asked == self.mode,
            "--background {} but {what} trained with --background {}; pass --background {}",
            asked.name(),
            self.mode.name(),
            self.mode.name()
        );
        Ok(())
    }
}
