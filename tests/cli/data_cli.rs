//! The `make-scene` and `inspect` commands end to end, and bad input giving exit code 1 with a
//! message naming the file (no panic).

use crate::data_common;

use std::process::Command;

/// Runs `alphasurf` with `args`: whether it succeeded, its stdout and stderr.
pub fn alphasurf(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_alphasurf"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn make_scene_then_inspect() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("thin");
    let o = out.to_str().unwrap();
    let (ok, stdout, stderr) = alphasurf(&[
        "make-scene",
        "--kind",
        "thin",
        "--out",
        o,
        "--res",
        "48",
        "--views",
        "10",
        "--seed",
        "4",
        "--gt-spacing",
        "0.01",
    ]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("wrote thin (13 views"), "{stdout}");
    for f in [
        "transforms_train.json",
        "transforms_val.json",
        "transforms_test.json",
        "gt_points.ply",
        "scene.json",
        "train/r_9.png",
        "val/r_0.png",
        "test/r_1.png",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let (ok, stdout, stderr) = alphasurf(&["inspect", o]);
    assert!(ok, "{stderr}");
    for want in [
        "train   10 views  48x48",
        "val      1 views",
        "test     2 views",
        "distance 4.000..4.000",
        "object bounds (visual hull",
    ] {
        assert!(stdout.contains(want), "missing '{want}' in:\n{stdout}");
    }
    assert!(!stdout.contains("warning"), "{stdout}");

    // Writing the same scene again is refused without --overwrite and replaces it with it; a
    // folder holding anything else is refused and left as it was.
    let small = [
        "--kind",
        "thin",
        "--res",
        "16",
        "--views",
        "2",
        "--gt-spacing",
        "0.05",
    ];
    let again = [&["make-scene", "--out", o][..], &small[..]].concat();
    let (ok, _, stderr) = alphasurf(&again);
    assert!(!ok && stderr.contains("pass --overwrite"), "{stderr}");
    let (ok, _, stderr) = alphasurf(&[&again[..], &["--overwrite"]].concat());
    assert!(ok, "{stderr}");
    let other = d.path().join("other");
    std::fs::create_dir(&other).unwrap();
    std::fs::write(other.join("transforms_train.json"), "mine").unwrap();
    let into_other = [
        &["make-scene", "--out", other.to_str().unwrap()][..],
        &small[..],
    ]
    .concat();
    let (ok, _, stderr) = alphasurf(&into_other);
    assert!(
        !ok && stderr.contains("other") && stderr.contains("not a scene written by make-scene"),
        "{stderr}"
    );
    assert_eq!(
        std::fs::read_to_string(other.join("transforms_train.json")).unwrap(),
        "mine"
    );
}

#[test]
fn inspect_fixture() {
    let f = data_common::fixture();
    let (ok, stdout, stderr) = alphasurf(&["inspect", f.to_str().unwrap(), "--downscale", "2"]);
    assert!(ok, "{stderr}");
    assert!(
        stdout.contains("train  100 views  128x128  focal 177.78"),
        "{stdout}"
    );
}

#[test]
fn bad_input_exits_with_a_clear_error() {
    let d = tempfile::tempdir().unwrap();
    let (ok, _, stderr) = alphasurf(&["inspect", d.path().join("absent").to_str().unwrap()]);
    assert!(
        !ok && stderr.contains("absent") && stderr.contains("does not exist"),
        "{stderr}"
    );
    data_common::write_dataset(d.path(), 1, 4, 4);
    std::fs::write(d.path().join("transforms_train.json"), "{\"frames\": [}").unwrap();
    let (ok, _, stderr) = alphasurf(&["inspect", d.path().to_str().unwrap()]);
    assert!(
        !ok && stderr.contains("transforms_train.json: malformed JSON at line 1, column 13"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
    let (ok, _, stderr) = alphasurf(&[
        "make-scene",
        "--kind",
        "solid",
        "--out",
        d.path().join("x").to_str().unwrap(),
        "--res",
        "0",
    ]);
    assert!(!ok && stderr.contains("--res"), "{stderr}");
}

/// `inspect` names the detected layout of the fixture's COLMAP and IDR copies.
#[test]
fn inspect_describes_colmap_and_idr_copies() {
    use data_common::convert::Target;
    for (target, want) in [
        (Target::ColmapBinary, "(COLMAP ("),
        (Target::ColmapText, "text))"),
        (Target::Idr, "(IDR/DTU (cameras_sphere.npz))"),
    ] {
        let (_keep, dir) = data_common::converted(&data_common::fixture(), target);
        let (ok, stdout, stderr) = alphasurf(&["inspect", dir.to_str().unwrap()]);
        assert!(ok, "{stderr}");
        for line in [
            want,
            "train  100 views  256x256",
            "val     10 views",
            "test    20 views",
        ] {
            assert!(
                stdout.contains(line),
                "{target:?}: no '{line}' in\n{stdout}"
            );
        }
        assert!(
            stdout.contains(
                "scene box (Blender units): [-1.500, -1.500, -1.500] .. [1.500, 1.500, 1.500]"
            ),
            "{stdout}"
        );
    }
}

/// `inspect` on a capture (COLMAP, no masks, no split file) states the split rule and prints the
/// foreground box and how it was found; `--box` sets the scene box; a malformed `--box` is an
/// error naming the flag.
#[test]
fn inspect_states_the_split_and_the_foreground_box_of_a_capture() {
    let f = data_common::shared_fixture("capture_birdcage");
    let dir = f.to_str().unwrap();
    let (ok, stdout, stderr) = alphasurf(&["inspect", dir]);
    assert!(ok, "{stderr}");
    for want in [
        "split: no split file: every 8th image by name",
        "foreground box (dataset units): [-0.6",
        "found from the cameras: optical axes of 96 cameras converge",
        "planes such as a floor or wall set aside",
    ] {
        assert!(stdout.contains(want), "missing {want:?} in:\n{stdout}");
    }
    let (ok, stdout, stderr) = alphasurf(&["inspect", dir, "--box", "-1,-1,-1,1,1,0"]);
    assert!(ok, "{stderr}");
    assert!(
        stdout.contains(
            "scene box (Blender units): [-1.000, -1.000, -1.500] .. [1.000, 1.000, 0.500]"
        ),
        "{stdout}"
    );
    let (ok, _, stderr) = alphasurf(&["inspect", dir, "--box", "-1,-1,-1,1,1"]);
    assert!(
        !ok && stderr.contains("--box") && stderr.contains("six numbers"),
        "{stderr}"
    );
}
