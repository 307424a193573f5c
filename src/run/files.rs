//! The names of the files in a run directory, which of them a run owns, and how a run folder is
//! recognised (its marker).

use std::path::Path;

/// The marker of a run directory: its description (stage, dataset, downscale, init).
pub const MARKER: &str = "run.json";
/// The lock file of a run being written.
pub const LOCK: &str = "run.lock";
/// End-of-run metrics.
pub const METRICS: &str = "metrics.json";
/// Per-step training log (CSV).
pub const TRAIN_LOG: &str = "train_log.csv";
/// Folder of the end-of-run test renders.
pub const TEST_RENDERS: &str = "test";
/// Stage-1 checkpoint (svox2 arrays + optimiser state).
pub const PLENOXELS_CHECKPOINT: &str = "plenoxels.npz";
/// Stage-2 checkpoint.
pub const SURFACE_CHECKPOINT: &str = "surface.npz";
/// `train --stage all`: the stage-1 run inside the parent run.
pub const ALL_STAGE1: &str = "plenoxels";
/// `train --stage all`: the stage-2 run inside the parent run.
pub const ALL_STAGE2: &str = "surface";

/// The files (directly in a run directory) that a run owns: an output path equal to one of
/// these inside a run is refused, and `--overwrite` removes them.
pub const OWNED_FILES: [&str; 6] = [
    MARKER,
    LOCK,
    METRICS,
    TRAIN_LOG,
    PLENOXELS_CHECKPOINT,
    SURFACE_CHECKPOINT,
];

/// Whether an entry (directly in a run directory) is the run's: one of [`OWNED_FILES`], the test
/// renders or the stage runs of a `--stage all` run.
pub fn is_run_entry(name: &str) -> bool {
    OWNED_FILES.contains(&name) || [TEST_RENDERS, ALL_STAGE1, ALL_STAGE2].contains(&name)
}

/// Whether `path` is a run directory (holds the marker).
pub fn is_run(path: &Path) -> bool {
    path.join(MARKER).is_file()
}
