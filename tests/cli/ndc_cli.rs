//! A forward-facing capture end to end in NDC: `inspect` says why `--space auto` picks it, both
//! stages train in it (recorded in run.json, taken over by stage 2), `render` renders in it,
//! `extract` writes the surfaces back in dataset units around the object, and the flags that cannot go with NDC are
//! refused with a message.

use crate::data_cli::alphasurf;
use crate::data_common::shared_fixture;
use std::path::Path;

fn path(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn a_forward_facing_capture_trains_and_extracts_in_ndc() {
    let data = shared_fixture("capture_fan_ff");
    let (ok, stdout, stderr) = alphasurf(&["inspect", path(&data)]);
    assert!(ok, "{stderr}");
    assert!(
        stdout.contains("grid space: NDC (every camera looks within 16.0° of their mean direction"),
        "{stdout}"
    );
    let (ok, stdout, _) = alphasurf(&["inspect", path(&data), "--space", "box"]);
    assert!(
        ok && stdout.contains("grid space: box (--space box)"),
        "{stdout}"
    );

    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let (ok, _, stderr) = alphasurf(&[
        "train",
        "--stage",
        "all",
        "--data",
        path(&data),
        "--out",
        path(&run),
        "--backend",
        "cpu",
        "--res",
        "32",
        "--iters",
        "150",
        "--surface-iters",
        "60",
        "--batch",
        "2048",
        "--category",
        "thin",
        "--quiet",
    ]);
    assert!(ok, "{stderr}");
    for stage in ["plenoxels", "surface"] {
        let info: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(run.join(stage).join("run.json")).unwrap(),
        )
        .unwrap();
        assert!(
            info["ndc"]["projection"]["near"].as_f64().unwrap() > 1.0,
            "{info}"
        );
        assert!(info.get("scene_box").is_none(), "{info}");
    }

    // `render` / `extract` of the stage-2 run on the CPU into `out`.
    let surface = run.join("surface");
    let of_surface = |command: &str, out: &Path, extra: &[&str]| {
        let args = [
            command,
            "--backend",
            "cpu",
            "--run",
            path(&surface),
            "--out",
            path(out),
        ];
        alphasurf(&[&args[..], extra].concat())
    };
    // `render` casts its rays in the run's recorded space: the test PSNR training reported.
    let (ok, stdout, stderr) = of_surface("render", &dir.path().join("renders"), &[]);
    assert!(ok, "{stderr}");
    let mean: f64 = stdout
        .lines()
        .find_map(|l| l.strip_prefix("mean PSNR "))
        .and_then(|l| l.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .expect("mean PSNR line");
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(surface.join("metrics.json")).unwrap())
            .unwrap();
    let trained = metrics["test_psnr"].as_f64().unwrap();
    assert!(
        (mean - trained).abs() < 0.01,
        "render {mean} vs train {trained}"
    );

    // Points back in dataset units: most of the surface the views see lies within the room's
    // front half, around the fan (2.7 to 4 units from the cameras), not at NDC coordinates.
    let pts = dir.path().join("points.ply");
    let (ok, extracted, stderr) = of_surface("extract", &pts, &[]);
    assert!(ok, "{stderr}");
    // The hidden-surface trim is off by default in NDC and looks toward the cameras when asked.
    assert!(!extracted.contains("hidden surfaces"), "{extracted}");
    let trimmed_ply = dir.path().join("trimmed.ply");
    let (ok, trimmed, _) = of_surface("extract", &trimmed_ply, &["--trim-hidden", "on"]);
    assert!(
        ok && trimmed.contains("seen by a training camera"),
        "{trimmed}"
    );
    let (ok, stdout, stderr) = alphasurf(&[
        "eval",
        "--json",
        "--pred",
        path(&pts),
        "--gt",
        path(&data.join("gt_points.ply")),
    ]);
    assert!(ok, "{stderr}");
    let e: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap()).unwrap();
    // Completeness over the GT points a training view sees (the scene.json's mask), inside
    // the eval box: well under the box's 1.8-unit size when the points are where the fan is.
    let s2d = e["metrics"]["mean_s2d"].as_f64().unwrap();
    assert!(s2d < 0.05, "mean GT → pred distance {s2d}: {e}");

    // Stage 2 from the NDC stage-1 checkpoint file takes its run's space; asking for a box
    // there is refused.
    let ckpt = run.join("plenoxels").join("plenoxels.npz");
    let (ok, _, stderr) = alphasurf(&[
        "train",
        "--stage",
        "surface",
        "--init",
        path(&ckpt),
        "--data",
        path(&data),
        "--out",
        path(&dir.path().join("s2box")),
        "--space",
        "box",
    ]);
    assert!(!ok && stderr.contains("was trained in NDC"), "{stderr}");

    // What cannot go with NDC.
    let (ok, _, stderr) = alphasurf(&[
        "train",
        "--stage",
        "plenoxels",
        "--data",
        path(&data),
        "--out",
        path(&dir.path().join("r2")),
        "--space",
        "ndc",
        "--box",
        "-1,-1,-1,1,1,1",
    ]);
    assert!(!ok && stderr.contains("--box and --space ndc"), "{stderr}");
    let p2 = dir.path().join("p2.ply");
    let (ok, _, stderr) = of_surface("extract", &p2, &["--scene-scale", "0.5"]);
    assert!(!ok && stderr.contains("trained in NDC"), "{stderr}");
    let (ok, _, stderr) = alphasurf(&[
        "train",
        "--stage",
        "plenoxels",
        "--data",
        path(&shared_fixture("capture_birdcage")),
        "--out",
        path(&dir.path().join("r3")),
        "--space",
        "ndc",
        "--iters",
        "1",
    ]);
    assert!(
        !ok && stderr.contains("--space ndc needs a forward-facing capture"),
        "{stderr}"
    );
}
