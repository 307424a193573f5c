//! `train --resume`, the part both stages share: require the run's checkpoint, restore it, let
//! `--iters` change the run's length, and stop when the run already has all its steps.

use anyhow::{ensure, Result};
use std::path::Path;

/// Resumes the run whose checkpoint is `ckpt`: `restore` builds the backend from it and returns
/// `(backend, step reached, configuration)`; `iters` (when given) replaces the step count that
/// `total` points at in the configuration. Returns `(backend, configuration, step)`, or `None`
/// (after saying so on stdout) when the run is already at its last step.
pub fn resume<B, C>(
    ckpt: &Path,
    iters: Option<u32>,
    total: impl FnOnce(&mut C) -> &mut u32,
    restore: impl FnOnce() -> Result<(B, u32, C)>,
) -> Result<Option<(B, C, u32)>> {
    ensure!(
        ckpt.exists(),
        "--resume: no checkpoint at {}",
        ckpt.display()
    );
    let (backend, step, mut cfg) = restore()?;
    let total = total(&mut cfg);
    if let Some(n) = iters {
        *total = n; // extend (or shorten) the run; the schedules keep their lengths
    }
    if step >= *total {
        println!(
            "{} is already at step {step} of {}: nothing to train (pass --iters to extend)",
            ckpt.display(),
            total
        );
        return Ok(None);
    }
    eprintln!("resuming {} at step {step} of {}", ckpt.display(), total);
    Ok(Some((backend, cfg, step)))
}
