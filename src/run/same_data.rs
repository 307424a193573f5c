//! Whether a run was trained on the dataset a command is given: `--resume` and `--init` compare
//! the dataset identity and normalisation a run recorded ([`super::identity`]) with the given
//! dataset's, and refuse another one unless the user says so (`--allow-other-data`): a grid
//! trained on one scene and normalisation is meaningless on another.

use super::dir::RunInfo;
use anyhow::{bail, Result};
use std::path::Path;

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
    use crate::run::identity::DataIdentity;

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
