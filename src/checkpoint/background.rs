//! A run's background as its checkpoints and metrics record it: the mode, the colour and, when
//! it is learned, the optimiser's running average; its spheres' shape (their texel values and
//! running averages are arrays of the checkpoint, [`SPHERE_ARRAYS`]); carried from stage 1 into
//! stage 2.

use super::format::{self, OptimArrays};
use crate::abi::buffers::{Background, BackgroundSpheres};
use crate::data::{BackgroundMode, Dataset};
use crate::math::background_msi::SphereTable;
use crate::stage::{Stage, StageBackend};
use anyhow::{bail, ensure, Context, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Key of the record in a checkpoint's metadata.
pub const META_KEY: &str = "background";

/// Names of the spheres' texel values and running averages among a checkpoint's arrays.
pub const SPHERE_ARRAYS: [&str; 2] = ["background_spheres", "background_spheres_avg"];

/// What a run shows behind its grid, as a checkpoint holds it: the background's record and its
/// spheres (texel values and running averages), kept (stage 2, `render`) or learned (stage 1).
pub struct Backdrop {
    pub record: BackgroundRecord,
    pub spheres: Option<SphereTable>,
}

impl Backdrop {
    /// The backdrop of the checkpoint at `path` (`meta`: its metadata, `optim`: its arrays),
    /// its spheres kept.
    pub fn kept(meta: &serde_json::Value, optim: &OptimArrays, path: &Path) -> Result<Self> {
        let record = BackgroundRecord::from_meta(meta, path)?;
        let spheres = record.spheres_in(optim, false, path)?;
        Ok(Backdrop { record, spheres })
    }

    /// Give `backend` this background and its spheres.
    pub fn install<S: Stage, B: StageBackend<S> + ?Sized>(self, backend: &mut B) -> Result<()> {
        backend.set_background(self.record.kernel())?;
        backend.set_spheres(self.spheres)
    }
}

/// The shape of a background's spheres (`abi::buffers::BackgroundSpheres` without addresses).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SpheresShape {
    pub centre: [f32; 3],
    pub layers: u32,
    pub size: u32,
    pub inv_r0: f32,
    pub inv_step: f32,
}

impl SpheresShape {
    fn of(s: &BackgroundSpheres) -> Self {
        SpheresShape {
            centre: s.centre,
            layers: s.layers,
            size: s.size,
            inv_r0: s.inv_r0,
            inv_step: s.inv_step,
        }
    }

    fn spheres(&self, learn: bool) -> BackgroundSpheres {
        BackgroundSpheres {
            centre: self.centre,
            layers: self.layers,
            size: self.size,
            inv_r0: self.inv_r0,
            inv_step: self.inv_step,
            learn: u32::from(learn),
            ..Default::default()
        }
    }
}

/// The background of a run at a step (default: white, of runs that did not record one).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct BackgroundRecord {
    pub mode: BackgroundMode,
    /// The colour composited behind every ray.
    pub rgb: [f32; 3],
    /// RMSProp running average of a learned colour's gradient (zero when fixed).
    pub avg: [f32; 3],
    /// The spheres in front of the colour (`--background spheres`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spheres: Option<SpheresShape>,
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
            spheres: None,
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

    /// The spheres a run of this background starts stage 1 with on `data`: around the grid
    /// box, in the colour the record starts with.
    pub fn start_spheres(&self, data: &Dataset) -> Result<Option<SphereTable>> {
        if !self.mode.spheres() {
            return Ok(None);
        }
        let scene = &data.scene;
        if scene.ndc.is_some() {
            bail!(
                "--background spheres: {} trains in NDC (a forward-facing capture), whose grid \
                 reaches infinite depth already; use --background learned, or --space box",
                data.root.display()
            );
        }
        let cameras: Vec<[f32; 3]> = data
            .train
            .frames
            .iter()
            .map(|f| scene.to_scaled(f.camera.centre()).to_array())
            .collect();
        let centre = scene.centre.to_array();
        Ok(Some(SphereTable::around(
            centre,
            scene.radius,
            &cameras,
            self.rgb,
        )))
    }

    /// What a backend holds, of a run in `mode`.
    pub fn of(mode: BackgroundMode, bg: &Background, spheres: Option<&SphereTable>) -> Self {
        BackgroundRecord {
            mode,
            rgb: bg.rgb,
            avg: bg.avg,
            spheres: spheres.map(|s| SpheresShape::of(&s.shape)),
        }
    }

    /// The spheres this record names, read from its checkpoint at `path` (only their arrays),
    /// learned or not.
    pub fn read_spheres(&self, path: &Path, learn: bool) -> Result<Option<SphereTable>> {
        if self.spheres.is_none() {
            return Ok(None);
        }
        let arrays = format::read_named(path, &SPHERE_ARRAYS)?;
        self.spheres_in(&arrays, learn, path)
    }

    /// The spheres this record names, from the arrays of its checkpoint at `path` (`arrays`:
    /// by name), learned or not. `None` when it has none.
    pub fn spheres_in(
        &self,
        arrays: &OptimArrays,
        learn: bool,
        path: &Path,
    ) -> Result<Option<SphereTable>> {
        let Some(shape) = &self.spheres else {
            return Ok(None);
        };
        let shape = shape.spheres(learn);
        let [table, avg] = SPHERE_ARRAYS.map(|name| format::optim_array(arrays, name, path));
        let (table, avg) = (table?, avg?);
        ensure!(
            table.len() == shape.table_len() && avg.len() == table.len(),
            "{}: the background spheres ({} of {}² texels) need {} values; the arrays hold {} \
             and {}",
            path.display(),
            shape.layers,
            shape.size,
            shape.table_len(),
            table.len(),
            avg.len()
        );
        Ok(Some(SphereTable { shape, table, avg }))
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
        let shape_finite = r.spheres.is_none_or(|s| {
            s.centre
                .iter()
                .chain([&s.inv_r0, &s.inv_step])
                .all(|x| x.is_finite())
                && s.inv_r0 > 0.0
                && s.inv_r0 - s.inv_step * s.layers.saturating_sub(1) as f32 > 0.0
        });
        ensure!(
            shape_finite && r.rgb.iter().chain(&r.avg).all(|x| x.is_finite()),
            "{}: metadata '{META_KEY}' has a non-finite value: {r:?}",
            path.display()
        );
        Ok(r)
    }

    /// Refuse a run whose `--background` differs from this record's (`what` names the record's
    /// source): the images were composited, and the grid trained, on this one. `auto` takes
    /// the record's.
    pub fn ensure_mode(&self, asked: BackgroundMode, what: &str) -> Result<()> {
        ensure!(
            asked == self.mode || asked == BackgroundMode::Auto,
            "--background {} but {what} trained with --background {}; pass --background {}",
            asked.name(),
            self.mode.name(),
            self.mode.name()
        );
        Ok(())
    }
}
