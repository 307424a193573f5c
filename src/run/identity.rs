//! A dataset's identity as a run records it: a content fingerprint (every split's image names,
//! sizes, camera poses and a sample of their pixels) and the scene normalisation the run trained
//! with. `--resume` and
//! `--init` compare it with the dataset they are given and refuse another one unless the user
//! says so (`--allow-other-data`): a grid trained on one scene and normalisation is meaningless
//! on another.

use super::dir::RunInfo;
use crate::data::Dataset;
use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// What `run.json` records of the dataset beside its path (see the module documentation).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DataIdentity {
    /// FNV-1a (64-bit, hex) over every split's name and, per view, its image file name, image
    /// size, camera-to-world matrix (f32 bits) and [`PIXEL_SAMPLES`] of its pixels (two scenes
    /// rendered from the same cameras differ only there; their alpha, and their colour where
    /// opaque, so the background they are composited on does not enter).
    pub fingerprint: String,
    /// The scene box's centre (scaled units).
    pub scene_centre: [f32; 3],
    /// The scene box's half-size (scaled units).
    pub scene_radius: f32,
}

impl DataIdentity {
    /// The identity of a loaded dataset.
    pub fn of(data: &Dataset) -> DataIdentity {
        let mut h = Fnv1a::new();
        for split in data.splits() {
            h.write(split.name.as_bytes());
            h.write(&[0]);
            for f in &split.frames {
                let name = f.file.file_name().unwrap_or_default();
                h.write(name.to_string_lossy().as_bytes());
                h.write(&[0]);
                h.write(&f.image.width.to_le_bytes());
                h.write(&f.image.height.to_le_bytes());
                for v in f.camera.c2w.to_cols_array() {
                    h.write(&v.to_bits().to_le_bytes());
                }
                let pixels = f.image.data.chunks_exact(4);
                let stride = (pixels.len() / PIXEL_SAMPLES).max(1);
                // Alpha, and the colour where it is opaque: what the background (a run's own
                // choice, checked on its own) does not change.
                for p in pixels.step_by(stride) {
                    h.write(if p[3] == 255 { p } else { &p[3..] });
                }
            }
        }
        DataIdentity {
            fingerprint: format!("{:016x}", h.0),
            scene_centre: data.scene.centre.to_array(),
            scene_radius: data.scene.radius,
        }
    }
}

/// Pixels per view that enter the fingerprint, evenly spaced (cheap next to loading).
pub const PIXEL_SAMPLES: usize = 4096;

/// FNV-1a, 64-bit: a stable hash (the standard library's may change between releases).
struct Fnv1a(u64);

impl Fnv1a {
    fn new() -> Self {
        Fnv1a(0xcbf2_9ce4_8422_2325)
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 ^ b as u64).wrapping_mul(0x0100_0000_01b3);
        }
    }
}

/// How the dataset `now` (this command's `run.json` to be) differs from the one `recorded`:
/// content (fingerprint; by path where a run from before it was recorded has none) and scene
/// normalisation. Empty when they agree.
pub fn differences(recorded: &RunInfo, now: &RunInfo) -> Vec<String> {
    let mut diffs = Vec::new();
    match (&recorded.identity, &now.identity) {
        (Some(a), Some(b)) => {
            if a.fingerprint != b.fingerprint {
                diffs.push(format!(
                    "its images, sizes, camera poses or pixels differ (fingerprint {} there, {} here)",
                    a.fingerprint, b.fingerprint
                ));
            }
            if a.scene_centre != b.scene_centre || a.scene_radius != b.scene_radius {
                diffs.push(format!(
                    "the scene box differs (centre {:?} radius {} there, centre {:?} radius {} \
                     here)",
                    a.scene_centre, a.scene_radius, b.scene_centre, b.scene_radius
                ));
            }
        }
        _ if recorded.data != now.data => diffs.push(format!(
            "it is another folder ({} there, {} here)",
            recorded.data.display(),
            now.data.display()
        )),
        _ => {}
    }
    if let (Some(a), Some(b)) = (recorded.scene_scale, now.scene_scale) {
        if a != b {
            diffs.push(format!("the scene scale differs ({a} there, {b} here)"));
        }
    }
    diffs
}

/// Refuse to use `run` (recorded as `recorded`) with the dataset `now` describes when it differs
/// ([`differences`]); with `allow` (`--allow-other-data`) only warn. `what` is the flag that
/// names the run (`--resume`, `--init`).
pub fn check_same_data(
    what: &str,
    run: &Path,
    recorded: &RunInfo,
    now: &RunInfo,
    allow: bool,
) -> Result<()> {
    let diffs = differences(recorded, now);
    if diffs.is_empty() {
        return Ok(());
    }
    let said = format!(
        "{what} {} was trained on the dataset {}, and --data {} is not that one: {}",
        run.display(),
        recorded.data.display(),
        now.data.display(),
        diffs.join("; ")
    );
    if allow {
        eprintln!("warning: {said} (continuing: --allow-other-data)");
        return Ok(());
    }
    bail!("{said}. Give the run's dataset, or pass --allow-other-data to use this one anyway")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::BackgroundMode;

    fn info(data: &str, id: Option<(&str, f32)>, scale: Option<f32>) -> RunInfo {
        RunInfo {
            stage: None,
            data: data.into(),
            downscale: 1,
            background: BackgroundMode::White,
            scene_scale: scale,
            scene_box: None,
            ndc: None,
            identity: id.map(|(f, r)| DataIdentity {
                fingerprint: f.into(),
                scene_centre: [0.0; 3],
                scene_radius: r,
            }),
            init: None,
            imported_from: None,
        }
    }

    #[test]
    fn another_dataset_or_normalisation_is_named_and_a_copy_is_not() {
        let now = info("/b", Some(("f1", 1.0)), Some(0.5));
        // A copy of the same content elsewhere: the same data.
        assert!(differences(&info("/a", Some(("f1", 1.0)), Some(0.5)), &now).is_empty());
        let d = differences(&info("/a", Some(("f2", 2.0)), Some(0.8)), &now);
        assert_eq!(d.len(), 3, "{d:?}");
        // A run from before fingerprints: compared by path.
        assert!(differences(&info("/b", None, None), &now).is_empty());
        let d = differences(&info("/a", None, None), &now);
        assert!(d[0].contains("another folder"), "{d:?}");
        let run = Path::new("/runs/r");
        let err = check_same_data("--resume", run, &info("/a", None, None), &now, false)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("--allow-other-data") && err.contains("/runs/r"),
            "{err}"
        );
        check_same_data("--resume", run, &info("/a", None, None), &now, true).unwrap();
    }
}
