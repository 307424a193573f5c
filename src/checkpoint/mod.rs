//! Checkpoints, in one place: the npz layout of each stage ([`format`]: the stage-1 grid and
//! what every checkpoint adds; [`surface`]: the stage-2 grid), the metadata a checkpoint records
//! (stage, step, configuration, [`BackgroundRecord`]), the writes of a training run (now, or on
//! the checkpoint thread of [`writer`]) and the resume, written once for both stages over
//! [`Stage`].

pub mod background;
pub mod format;
pub mod surface;
pub mod writer;

pub use background::{Backdrop, BackgroundRecord};

use crate::abi::buffers::Background;
use crate::data::BackgroundMode;
use crate::math::background_msi::SphereTable;
use crate::stage::{Stage, StageBackend, StateArrays};
use anyhow::{Context, Result};
use serde::de::DeserializeOwned;
use serde_json::json;
use std::path::{Path, PathBuf};
use writer::BackgroundSave;

/// The checkpoint file of stage `S` in the run directory `run`.
pub fn path<S: Stage>(run: &Path) -> PathBuf {
    run.join(S::CHECKPOINT)
}

/// A training run's checkpoints of stage `S`: where they go, and the configuration and
/// background mode each records.
pub struct RunCheckpoints {
    pub path: PathBuf,
    /// The run's configuration, as recorded.
    pub config: serde_json::Value,
    pub mode: BackgroundMode,
}

impl RunCheckpoints {
    /// The metadata of the checkpoint of `step`, with the background `bg` and its `spheres`.
    fn meta<S: Stage>(
        &self,
        bg: &Background,
        spheres: Option<&SphereTable>,
        step: u32,
    ) -> serde_json::Value {
        let bg = BackgroundRecord::of(self.mode, bg, spheres);
        json!({
            "stage": S::NAME, "step": step, "config": self.config, background::META_KEY: bg
        })
    }

    /// Write the checkpoint of `step` atomically, now (refuses non-finite values).
    fn save<S: Stage, B: StageBackend<S> + ?Sized>(&self, backend: &B, step: u32) -> Result<()> {
        let spheres = backend.spheres()?;
        let meta = self.meta::<S>(&backend.background()?, spheres.as_ref(), step);
        backend
            .with_state(&mut |grid, state| {
                S::save(
                    &self.path,
                    grid,
                    &named::<S>(state, spheres.as_ref()),
                    &meta,
                )
            })
            .with_context(|| format!("after step {step}"))
    }

    /// The checkpoint of `step` as a write for the checkpoint thread: the grid and the running
    /// averages are copied (downloaded from a GPU) now, checked and written atomically there.
    fn snapshot<S: Stage, B: StageBackend<S> + ?Sized>(
        &self,
        backend: &B,
        step: u32,
    ) -> Result<impl FnOnce() -> Result<()> + Send + 'static> {
        let spheres = backend.spheres()?;
        let meta = self.meta::<S>(&backend.background()?, spheres.as_ref(), step);
        let grid = backend.grid()?;
        let state = backend.optimizer_state()?;
        let path = self.path.clone();
        Ok(move || {
            S::save(
                &path,
                &grid,
                &named::<S>(&state.arrays(), spheres.as_ref()),
                &meta,
            )
            .with_context(|| format!("after step {step}"))
        })
    }

    /// Checkpoint `step` with `writer`: on its thread from a copy, or now in place when a copy
    /// does not fit in memory (`BackgroundSave::checkpoint`).
    pub fn write<S: Stage, B: StageBackend<S> + ?Sized>(
        &self,
        writer: &mut BackgroundSave,
        backend: &B,
        step: u32,
    ) -> Result<()> {
        writer.checkpoint(
            backend.state_bytes(),
            || self.snapshot(backend, step),
            || self.save(backend, step),
        )
    }
}

/// The optimiser arrays with their names, and the background spheres' arrays.
fn named<'a, S: Stage>(
    state: &[&'a [f32]],
    spheres: Option<&'a SphereTable>,
) -> Vec<(&'static str, &'a [f32])> {
    let mut arrays: Vec<_> = S::STATE_NAMES
        .iter()
        .copied()
        .zip(state.iter().copied())
        .collect();
    if let Some(s) = spheres {
        arrays.extend(
            background::SPHERE_ARRAYS
                .into_iter()
                .zip([&s.table[..], &s.avg[..]]),
        );
    }
    arrays
}

/// A configuration a checkpoint records.
pub trait Recorded: serde::Serialize + DeserializeOwned {
    /// Refuse values the stage cannot train with.
    fn validate(&self) -> Result<()>;
    /// The run's step count (what `--resume --iters` replaces).
    fn iters_mut(&mut self) -> &mut u32;
}

/// What [`resume`] restores: the backend holding the checkpoint's grid, optimiser state and
/// background, the next step, the configuration and the background's record.
pub type Restored<B, C> = (Box<B>, u32, C, BackgroundRecord);

/// Open the checkpoint of stage `S` at `path` (read once): its configuration and background
/// checked, then the backend `make` builds on its grid given its optimiser state, background and
/// spheres.
pub fn resume<S: Stage, C: Recorded, B: StageBackend<S> + ?Sized>(
    make: impl FnOnce(S::Grid) -> Result<Box<B>>,
    path: &Path,
) -> Result<Restored<B, C>> {
    let saved = S::load(path)?;
    let (step, cfg) = format::meta_step_config::<C>(&saved.meta, S::NAME, path)?;
    cfg.validate()
        .with_context(|| format!("{}: invalid configuration", path.display()))?;
    let bg = BackgroundRecord::from_meta(&saved.meta, path)?;
    let mut backend = make(saved.grid)?;
    backend
        .load_state(saved.state)
        .with_context(|| format!("{}: optimiser state", path.display()))?;
    Backdrop {
        record: bg,
        spheres: saved.spheres,
    }
    .install(backend.as_mut())?;
    Ok((backend, step, cfg, bg))
}

/// The background spheres a checkpoint of stage `S` holds (learned if `S` trains them), from its
/// metadata and arrays.
pub fn spheres_of<S: Stage>(
    optim: &format::OptimArrays,
    meta: &serde_json::Value,
    path: &Path,
) -> Result<Option<SphereTable>> {
    BackgroundRecord::from_meta(meta, path)?.spheres_in(optim, S::TRAINS_SPHERES, path)
}

/// The optimiser arrays named by `S::STATE_NAMES`, from a loaded checkpoint's arrays.
pub fn state_of<S: Stage>(optim: &format::OptimArrays, path: &Path) -> Result<S::State> {
    let arrays = S::STATE_NAMES
        .iter()
        .map(|name| format::optim_array(optim, name, path))
        .collect::<Result<Vec<_>>>()?;
    S::State::from_arrays(arrays)
}
