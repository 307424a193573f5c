//! Run directories: a run's marker ([`MARKER`], `run.json`), its lock ([`LOCK`]) and the rules
//! for writing into a folder (the file names themselves are in [`super::files`]).
//!
//! A writer claims a folder with [`RunDir::claim`]:
//! - a new or empty folder becomes a run;
//! - an existing run is continued with [`Open::Resume`] or replaced with [`Open::Overwrite`]
//!   (which removes only the files a run owns, so anything else the user put there survives,
//!   and only when the new run writes its marker: a command that fails on its inputs before
//!   then leaves the previous run whole);
//!   [`Open::Fresh`] refuses it;
//! - a non-empty folder that is not a run is always refused;
//! - a folder that equals, or lies inside, an input or a dataset is refused;
//! - a second writer is kept out by the lock (process id and host) until the first ends.
//!
//! Readers (`render`, `export`, `extract`, stage 2's `--init`) use [`read_info`] and the
//! checkpoint paths; commands that write single files outside runs check them with
//! [`super::outputs`].

pub use super::files::*;
use super::identity::DataIdentity;
use super::lock::Lock;
use super::outputs::{check_not_inside_inputs, dataset_containing};
use super::replace::Replacement;
use crate::data::ndc::Ndc;
use crate::data::{Aabb, BackgroundMode, SceneBox};
use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use std::fs;
use std::path::{Path, PathBuf};

/// What a run directory holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RunStage {
    /// A stage-1 (Plenoxels) run: `plenoxels.npz`.
    Plenoxels,
    /// A stage-2 (αSurf) run: `surface.npz`.
    Surface,
    /// `train --stage all`: a stage-1 run in `plenoxels/` and a stage-2 run in `surface/`.
    All,
}

impl RunStage {
    /// The name used in messages and `run.json`.
    pub fn name(self) -> &'static str {
        match self {
            RunStage::Plenoxels => "plenoxels",
            RunStage::Surface => "surface",
            RunStage::All => "all",
        }
    }
}

/// The contents of `run.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunInfo {
    /// Which stage wrote the run (absent in runs written before it was recorded: then inferred
    /// from the checkpoint present, see [`read_info`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stage: Option<RunStage>,
    /// The dataset's absolute path.
    pub data: PathBuf,
    /// Image downscale factor used in training.
    pub downscale: u32,
    /// `--background` as the data resolved it: what the images were composited on and training
    /// composited on (absent in runs written before it was recorded: white). A learned colour
    /// and spheres are in the checkpoints (the colour also in metrics.json).
    #[serde(default = "BackgroundMode::unrecorded")]
    pub background: BackgroundMode,
    /// Dataset units → the grid's world (the scene box's scale the run trained with; `extract`
    /// writes points back in dataset units with it). Absent in runs written before it was
    /// recorded and in imports: the NeRF-synthetic 2/3.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scene_scale: Option<f32>,
    /// The grid's cube in dataset units (absent in runs written before it was recorded and in
    /// imports).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scene_box: Option<Aabb>,
    /// The NDC space the grid lies in (forward-facing captures trained with `--space ndc` or
    /// `auto`'s choice of it); then `scene_box` is absent and `extract` maps points back through
    /// it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ndc: Option<Ndc>,
    /// The dataset's content fingerprint and scene box ([`super::identity`]), which `--resume`
    /// and `--init` compare; absent in runs written before it was recorded and in imports.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub identity: Option<DataIdentity>,
    /// Stage 2: the stage-1 run or checkpoint it was initialised from.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub init: Option<PathBuf>,
    /// `import`: the svox2 checkpoint the run was made from.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub imported_from: Option<PathBuf>,
}

impl RunInfo {
    /// The grid's space as the run recorded it: its cube (none in NDC) and the normalisation
    /// exactly as the run had it (its scale and identity, or its NDC space), so that an identity
    /// check compares equal values; `None` for a run that recorded no box.
    pub fn scene(&self) -> Option<(Option<Aabb>, SceneBox)> {
        if let Some(ndc) = self.ndc {
            return Some((None, SceneBox::in_ndc(ndc)));
        }
        let cube = self.scene_box?;
        let exact = match (self.scene_scale, &self.identity) {
            (Some(scale), Some(id)) => SceneBox {
                scale,
                centre: id.scene_centre.into(),
                radius: id.scene_radius,
                ndc: None,
            },
            _ => cube.scene_box(),
        };
        Some((Some(cube), exact))
    }
}

/// How a writer opens a run directory.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Open {
    /// A new run: the folder must be missing, empty, or not yet hold anything.
    Fresh,
    /// Continue the run already there (`--resume`).
    Resume,
    /// Replace the run already there (`--overwrite`); a folder that is not a run is still
    /// refused.
    Overwrite,
}

/// A run directory claimed for writing; holds its lock until dropped.
#[derive(Debug)]
pub struct RunDir {
    path: PathBuf,
    stage: RunStage,
    /// `Open::Overwrite`: the previous run's files are still to be removed.
    replace_pending: bool,
    _lock: Lock,
}

/// The entries of a folder other than a lock file (a run killed between taking the lock and
/// writing its marker leaves only that).
fn entries_besides_lock(path: &Path) -> Result<Vec<String>> {
    let mut names = Vec::new();
    for e in fs::read_dir(path).with_context(|| format!("reading {}", path.display()))? {
        let name = e?.file_name().to_string_lossy().into_owned();
        if name != LOCK {
            names.push(name);
        }
    }
    names.sort();
    Ok(names)
}

impl RunDir {
    /// Claim `path` for a run of `stage`, under the rules in the module documentation. `inputs`
    /// are the files and folders the run reads (the dataset, the stage-1 run): the run may not be
    /// one of them or lie inside one. On success the folder exists and is locked; with
    /// [`Open::Overwrite`] the previous run's files are removed by [`RunDir::write_info`].
    pub fn claim(path: &Path, stage: RunStage, open: Open, inputs: &[&Path]) -> Result<RunDir> {
        let shown = path.display();
        if path.exists() && !path.is_dir() {
            bail!("--out {shown} is a file, not a run directory");
        }
        if let Some(ds) = dataset_containing(path) {
            bail!(
                "--out {shown} lies inside the dataset {}: its images would be overwritten; \
                 choose a folder outside it",
                ds.display()
            );
        }
        check_not_inside_inputs(path, inputs)?;
        let existing = path.is_dir();
        let mut open = open;
        if existing {
            if is_run(path) {
                let info = read_info(path)?;
                let had = info.stage.unwrap_or(stage);
                // A run stopped before its first checkpoint holds nothing trained: a new run
                // replaces it, and there is nothing to resume.
                if !holds_checkpoint(path) {
                    if open == Open::Resume {
                        bail!(
                            "--resume: {shown} holds no checkpoint (the run stopped before its \
                             first one); start it again without --resume"
                        );
                    }
                    if open == Open::Fresh {
                        eprintln!(
                            "{shown} holds a {} run stopped before its first checkpoint \
                             (nothing trained): replacing it",
                            had.name()
                        );
                        open = Open::Overwrite;
                    }
                }
                match open {
                    Open::Fresh => bail!(
                        "--out {shown} already holds a {} run; pass --resume to continue it or \
                         --overwrite to replace it",
                        had.name()
                    ),
                    Open::Resume if had != stage => bail!(
                        "--resume: {shown} is a {} run, not a {} run",
                        had.name(),
                        stage.name()
                    ),
                    Open::Resume | Open::Overwrite => {}
                }
            } else {
                let names = entries_besides_lock(path)?;
                if !names.is_empty() {
                    bail!(
                        "--out {shown} is not empty and is not a run directory (no {MARKER}; it \
                         holds {}{}): choose a new or empty folder (--overwrite only replaces a \
                         run)",
                        names[..names.len().min(3)].join(", "),
                        if names.len() > 3 { ", …" } else { "" }
                    );
                }
                if open == Open::Resume {
                    bail!("--resume: {shown} holds no run to continue");
                }
            }
        } else if open == Open::Resume {
            bail!("--resume: there is no run at {shown}");
        }
        fs::create_dir_all(path).with_context(|| format!("creating run directory {shown}"))?;
        let lock = Lock::acquire(&path.join(LOCK))?;
        Ok(RunDir {
            path: path.to_path_buf(),
            stage,
            replace_pending: open == Open::Overwrite,
            _lock: lock,
        })
    }

    /// The run directory.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The stage it was claimed for.
    pub fn stage(&self) -> RunStage {
        self.stage
    }

    /// A file inside the run.
    pub fn file(&self, name: &str) -> PathBuf {
        self.path.join(name)
    }

    /// Write the marker `run.json` (atomically); its `stage` is the claimed one. A run claimed
    /// with [`Open::Overwrite`] first removes the previous run's files: call this once the
    /// command's inputs are known good.
    pub fn write_info(&mut self, info: &RunInfo) -> Result<()> {
        if self.replace_pending {
            remove_run_files(&self.path)?;
            self.replace_pending = false;
        }
        write_marker(&self.path, self.stage, info)
    }

    /// Write the whole run at once (`import`): `fill` writes its files into a folder beside the
    /// run, the marker is added, and that folder replaces the run only when complete
    /// ([`super::replace`]); the entries of a previous run that are not a run's stay.
    pub fn write_whole(self, info: &RunInfo, fill: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
        let staged = Replacement::begin(&self.path, is_run_entry)?;
        fill(staged.path())?;
        write_marker(staged.path(), self.stage, info)?;
        staged.commit()
    }

    /// Write `metrics.json` (atomically).
    pub fn write_metrics(&self, metrics: &impl Serialize) -> Result<()> {
        crate::io::atomic::write_json(&self.file(METRICS), &serde_json::to_value(metrics)?)
    }
}

/// Whether a run directory holds a checkpoint of either stage (of a `--stage all` run: its
/// stage-1 run's).
fn holds_checkpoint(path: &Path) -> bool {
    [
        path.join(PLENOXELS_CHECKPOINT),
        path.join(SURFACE_CHECKPOINT),
        path.join(ALL_STAGE1).join(PLENOXELS_CHECKPOINT),
    ]
    .iter()
    .any(|p| p.is_file())
}

/// Write `dir`'s marker for a run of `stage` (atomically).
fn write_marker(dir: &Path, stage: RunStage, info: &RunInfo) -> Result<()> {
    let info = RunInfo {
        stage: Some(stage),
        ..info.clone()
    };
    crate::io::atomic::write_json(&dir.join(MARKER), &serde_json::to_value(&info)?)
}

/// Remove the files a run owns (and its test renders, and the stage runs of a `--stage all`
/// run), keeping anything else. The lock is kept: it belongs to the new writer.
fn remove_run_files(path: &Path) -> Result<()> {
    let rm = |p: &Path| -> Result<()> {
        match fs::remove_file(p) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                Err(e).with_context(|| format!("--overwrite: removing {}", p.display()))
            }
            _ => Ok(()),
        }
    };
    for name in OWNED_FILES.iter().filter(|n| **n != LOCK) {
        let p = path.join(name);
        rm(&p)?;
        rm(&crate::io::atomic::temp_path(&p)?)?;
    }
    let renders = path.join(TEST_RENDERS);
    if renders.is_dir() {
        for e in fs::read_dir(&renders)? {
            let p = e?.path();
            let name = p.file_name().unwrap_or_default().to_string_lossy();
            if name.starts_with("r_") && name.ends_with(".png") {
                rm(&p)?;
            }
        }
        let _ = fs::remove_dir(&renders); // only when nothing else is in it
    }
    for sub in [ALL_STAGE1, ALL_STAGE2] {
        let p = path.join(sub);
        if is_run(&p) {
            remove_run_files(&p)?;
            let _ = fs::remove_dir(&p);
        }
    }
    Ok(())
}

/// Read a run directory's `run.json`; an old marker without `stage` gets the stage of the
/// checkpoint it holds.
pub fn read_info(run: &Path) -> Result<RunInfo> {
    let p = run.join(MARKER);
    let text = fs::read_to_string(&p).with_context(|| {
        format!(
            "{} is not a run directory (cannot read {})",
            run.display(),
            p.display()
        )
    })?;
    let mut info: RunInfo =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", p.display()))?;
    if info.stage.is_none() {
        info.stage = if run.join(SURFACE_CHECKPOINT).exists() {
            Some(RunStage::Surface)
        } else if run.join(PLENOXELS_CHECKPOINT).exists() {
            Some(RunStage::Plenoxels)
        } else {
            None
        };
    }
    Ok(info)
}

/// The stage-1 checkpoint of a run, for a command that reads a stage-1 grid (`render`,
/// `export`): a stage-2 or `--stage all` run is named as such instead of a bare missing file.
pub fn plenoxels_checkpoint(run: &Path, command: &str) -> Result<PathBuf> {
    let ck = run.join(PLENOXELS_CHECKPOINT);
    if ck.is_file() {
        return Ok(ck);
    }
    if run.join(SURFACE_CHECKPOINT).is_file() {
        bail!(
            "{command} reads a stage-1 (Plenoxels) run, and {} is a stage-2 (αSurf) run (it holds \
             {SURFACE_CHECKPOINT}, no {PLENOXELS_CHECKPOINT}); give its stage-1 run{}",
            run.display(),
            read_info(run)
                .ok()
                .and_then(|i| i.init)
                .map_or(String::new(), |i| format!(" ({})", i.display()))
        );
    }
    if run.join(ALL_STAGE1).join(PLENOXELS_CHECKPOINT).is_file() {
        bail!(
            "{} is a `--stage all` run: give its stage-1 run {}",
            run.display(),
            run.join(ALL_STAGE1).display()
        );
    }
    bail!(
        "{} holds no {PLENOXELS_CHECKPOINT}: not a trained stage-1 run",
        run.display()
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn info(data: &Path) -> RunInfo {
        RunInfo {
            stage: None,
            data: data.to_path_buf(),
            downscale: 1,
            background: BackgroundMode::White,
            scene_scale: None,
            scene_box: None,
            ndc: None,
            identity: None,
            init: None,
            imported_from: None,
        }
    }

    #[test]
    fn claiming_follows_the_rules() {
        let dir = tempfile::tempdir().unwrap();
        let data = dir.path().join("data");
        fs::create_dir(&data).unwrap();
        fs::write(data.join("transforms_train.json"), "{}").unwrap();
        let run = dir.path().join("run");
        // New folder: a run, locked.
        let mut r = RunDir::claim(&run, RunStage::Plenoxels, Open::Fresh, &[&data]).unwrap();
        r.write_info(&info(&data)).unwrap();
        fs::write(r.file(PLENOXELS_CHECKPOINT), "x").unwrap();
        let err = RunDir::claim(&run, RunStage::Plenoxels, Open::Resume, &[&data]).unwrap_err();
        assert!(
            format!("{err:#}").contains("already locked by this process"),
            "{err:#}"
        );
        fs::write(r.file(METRICS), "{}").unwrap();
        fs::write(run.join("notes.txt"), "mine").unwrap();
        drop(r);
        // Existing run: Fresh refused, Resume of another stage refused, Overwrite keeps user files.
        let err = RunDir::claim(&run, RunStage::Plenoxels, Open::Fresh, &[]).unwrap_err();
        assert!(format!("{err:#}").contains("--overwrite"), "{err:#}");
        let err = RunDir::claim(&run, RunStage::Surface, Open::Resume, &[]).unwrap_err();
        assert!(format!("{err:#}").contains("not a surface run"), "{err:#}");
        let mut r = RunDir::claim(&run, RunStage::Surface, Open::Overwrite, &[]).unwrap();
        assert!(
            run.join(METRICS).exists(),
            "nothing removed before the new marker"
        );
        r.write_info(&info(&data)).unwrap();
        assert!(!run.join(METRICS).exists());
        assert_eq!(read_info(&run).unwrap().stage, Some(RunStage::Surface));
        assert_eq!(fs::read_to_string(run.join("notes.txt")).unwrap(), "mine");
        drop(r);
        // A non-empty folder that is not a run: refused even with Overwrite.
        let other = dir.path().join("other");
        fs::create_dir(&other).unwrap();
        fs::write(other.join(METRICS), "mine").unwrap();
        for open in [Open::Fresh, Open::Overwrite] {
            let err = RunDir::claim(&other, RunStage::Plenoxels, open, &[]).unwrap_err();
            assert!(
                format!("{err:#}").contains("not a run"),
                "{open:?}: {err:#}"
            );
        }
        let err = RunDir::claim(&other, RunStage::Plenoxels, Open::Resume, &[]).unwrap_err();
        assert!(format!("{err:#}").contains("no run"), "{err:#}");
        assert_eq!(fs::read_to_string(other.join(METRICS)).unwrap(), "mine");
        // Inside a dataset, or equal to / inside an input.
        for bad in [data.clone(), data.join("test"), data.join("a/b")] {
            let err = RunDir::claim(&bad, RunStage::Plenoxels, Open::Fresh, &[]).unwrap_err();
            assert!(format!("{err:#}").contains("dataset"), "{err:#}");
        }
        let input = dir.path().join("input_run");
        fs::create_dir(&input).unwrap();
        for bad in [input.clone(), input.join("sub")] {
            let err = RunDir::claim(&bad, RunStage::Surface, Open::Fresh, &[&input]).unwrap_err();
            assert!(format!("{err:#}").contains("input"), "{err:#}");
        }
        // Resume where there is no run.
        let err = RunDir::claim(
            &dir.path().join("none"),
            RunStage::Surface,
            Open::Resume,
            &[],
        )
        .unwrap_err();
        assert!(format!("{err:#}").contains("no run"), "{err:#}");
        // A run stopped before its first checkpoint: nothing to resume, a new run replaces it.
        let stopped = dir.path().join("stopped");
        let mut r = RunDir::claim(&stopped, RunStage::Plenoxels, Open::Fresh, &[]).unwrap();
        r.write_info(&info(&data)).unwrap();
        drop(r);
        let err = RunDir::claim(&stopped, RunStage::Plenoxels, Open::Resume, &[]).unwrap_err();
        assert!(format!("{err:#}").contains("without --resume"), "{err:#}");
        RunDir::claim(&stopped, RunStage::Plenoxels, Open::Fresh, &[]).unwrap();
    }

    #[test]
    fn readers_name_the_kind_of_run() {
        let dir = tempfile::tempdir().unwrap();
        let run = dir.path().join("s2");
        fs::create_dir(&run).unwrap();
        fs::write(run.join(SURFACE_CHECKPOINT), "x").unwrap();
        fs::write(
            run.join(MARKER),
            r#"{"data": "/d", "downscale": 1, "init": "/runs/s1"}"#,
        )
        .unwrap();
        assert_eq!(read_info(&run).unwrap().stage, Some(RunStage::Surface));
        let err = format!("{:#}", plenoxels_checkpoint(&run, "render").unwrap_err());
        assert!(err.contains("stage-2") && err.contains("/runs/s1"), "{err}");
    }
}
