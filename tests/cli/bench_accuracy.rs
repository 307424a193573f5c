//! `alphasurf bench accuracy` end to end on two tiny generated scenes (one thin, one translucent):
//! the table, accuracy.json with per-scene and per-category figures, and a rerun that reuses every
//! finished scene instead of training again.

use std::path::Path;
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_alphasurf"))
}

fn run_ok(cmd: &mut Command) -> (String, String) {
    let out = cmd.output().expect("spawn alphasurf");
    let (o, e) = (
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    );
    assert!(out.status.success(), "{cmd:?} failed:\n{o}\n{e}");
    (o, e)
}

fn make_scene(kind: &str, out: &Path) {
    run_ok(
        bin()
            .args(["make-scene", "--kind", kind, "--out"])
            .arg(out)
            .args([
                "--res",
                "32",
                "--views",
                "12",
                "--spp",
                "1",
                "--gt-spacing",
                "0.02",
            ]),
    );
}

fn bench(scenes: &[&Path], out: &Path, extra: &[&str]) -> (String, String) {
    let mut c = bin();
    c.args([
        "bench",
        "accuracy",
        "--backend",
        "cpu",
        "--res",
        "16",
        "--iters",
        "60",
    ])
    .args([
        "--surface-iters",
        "20",
        "--batch",
        "1024",
        "--json",
        "--out",
    ])
    .arg(out)
    .arg("--data")
    .args(scenes)
    .args(extra);
    run_ok(&mut c)
}

#[test]
fn bench_accuracy_scores_each_scene_and_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let (thin, tr) = (dir.path().join("thin_a"), dir.path().join("translucent_b"));
    make_scene("thin", &thin);
    make_scene("translucent", &tr);
    let out = dir.path().join("acc");
    let (stdout, _) = bench(&[&thin, &tr], &out, &[]);
    assert!(stdout.contains("| thin_a | thin |"), "{stdout}");
    assert!(
        stdout.contains("| translucent_b | translucent |"),
        "{stdout}"
    );
    let json: serde_json::Value =
        serde_json::from_str(stdout.lines().last().unwrap()).expect("--json line");
    let scenes = json["scenes"].as_array().unwrap();
    assert_eq!(scenes.len(), 2);
    for s in scenes {
        let name = s["scene"].as_str().unwrap();
        assert_eq!(s["levels"].as_array().unwrap().len(), 6, "{name}");
        let best = s["best_chamfer_e2"].as_f64().unwrap();
        let surf = s["alphasurf_chamfer_e2"].as_f64().unwrap();
        assert!(
            best.is_finite() && best > 0.0 && surf.is_finite() && surf > 0.0,
            "{s}"
        );
        // The best level is the minimum of the sweep.
        let min = s["levels"]
            .as_array()
            .unwrap()
            .iter()
            .filter_map(|l| l["chamfer_e2"].as_f64())
            .fold(f64::INFINITY, f64::min);
        assert_eq!(best, min, "{name}");
        // Thin scenes also sweep the levels with their hidden cells trimmed (αSurf's own
        // extraction trims them there): the like-for-like baseline.
        let trimmed = s["trimmed_levels"].as_array().unwrap();
        assert_eq!(trimmed.len(), if name == "thin_a" { 6 } else { 0 }, "{s}");
        assert!(
            name != "thin_a" || trimmed.iter().any(|l| l["chamfer_e2"].as_f64().is_some()),
            "{s}"
        );
        assert!(s["stage1_psnr"].as_f64().unwrap() > 10.0, "{s}");
        assert!(s["stage2_psnr"].as_f64().unwrap() > 10.0, "{s}");
        assert!(out.join(name).join("result.json").is_file());
    }
    let cats: Vec<&str> = json["categories"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["category"].as_str().unwrap())
        .collect();
    assert_eq!(cats, ["thin", "translucent"]);
    assert_eq!(scenes[0]["scene"], "thin_a");
    sweep_matches_single_extractions(&out.join("thin_a"), &thin, &scenes[0]);

    // A rerun with the same settings trains nothing and gives the same table.
    let (again, err) = bench(&[&thin, &tr], &out, &[]);
    assert_eq!(err.matches("finished before").count(), 2, "{err}");
    assert!(!err.contains("stage 1 on"), "{err}");
    // The same table (the JSON line's floats pass through a text round trip, so compare the table).
    let table = |s: &str| {
        s.lines()
            .filter(|l| l.starts_with('|'))
            .map(String::from)
            .collect::<Vec<_>>()
    };
    assert_eq!(table(&again), table(&stdout));
    assert_eq!(table(&stdout).len(), 2 + 2 + 2, "{stdout}");

    // A stage-2 change on the same stage-1 runs: stage 1 is reused, stage 2 runs again.
    let out2 = dir.path().join("acc2");
    let (_, err) = bench(
        &[&thin],
        &out2,
        &["--stage1-from", out.to_str().unwrap(), "--seed", "1"],
    );
    assert!(err.contains("stage 1: reusing"), "{err}");
    assert!(out2.join("thin_a/alphasurf/metrics.json").is_file());
    assert!(!out2.join("thin_a/plenoxels").exists());

    // Other settings in the same output: both runs are trained again over the old ones.
    let (_, err) = bench(&[&thin], &out, &["--seed", "2"]);
    assert!(err.contains("holds a result for other settings"), "{err}");
    assert!(!err.contains("stage 1: reusing"), "{err}");
    let result: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("thin_a/result.json")).unwrap())
            .unwrap();
    assert_eq!(result["settings"]["stage1"]["seed"], 2);
    assert_eq!(result["settings"]["seed"], 2);

    // A run trained under other presets (an older build) is never scored as this build's: its
    // recorded configuration is compared with the one these flags give in this build.
    let edit = |path: &Path, key: &str, field: &str, value: serde_json::Value| {
        let mut m: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
        let config = &mut m["config"];
        match field {
            "" => config[key] = value,
            f => config[key][f] = value,
        }
        std::fs::write(path, serde_json::to_string(&m).unwrap()).unwrap();
    };
    // Stage 2: the scene is computed again on the same stage 1.
    let s2 = out.join("thin_a/alphasurf/metrics.json");
    edit(&s2, "lr_opacity", "init", 0.5.into());
    let (_, err) = bench(&[&thin], &out, &["--seed", "2"]);
    assert!(
        err.contains("stage-2 run had another configuration") && err.contains("lr_opacity"),
        "{err}"
    );
    assert!(err.contains("stage 1: reusing"), "{err}");
    // Stage 1: `--stage1-from` refuses it, and the output's own rerun trains it again.
    let s1 = out.join("thin_a/plenoxels/metrics.json");
    edit(&s1, "batch", "", 999.into());
    let refused = bin()
        .args(["bench", "accuracy", "--backend", "cpu", "--res", "16"])
        .args(["--iters", "60", "--surface-iters", "20", "--batch", "1024"])
        .args(["--seed", "2", "--stage1-from"])
        .arg(&out)
        .arg("--out")
        .arg(dir.path().join("acc3"))
        .arg("--data")
        .arg(&thin)
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success(), "{e}");
    assert!(e.contains("batch: 999 there, 1024 here"), "{e}");
    let (_, err) = bench(&[&thin], &out, &["--seed", "2"]);
    assert!(
        err.contains("batch: 999 there, 1024 here") && err.contains("training it again"),
        "{err}"
    );
    assert!(err.contains("stage 1 on"), "{err}");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&s1).unwrap()).unwrap();
    assert_eq!(m["config"]["batch"], 1024);
}

/// The level sweeps (the grid and the ground truth read once) give what `extract --levels L
/// [--trim-hidden on]` then `eval` give level by level: the same clouds byte for byte, the same
/// Chamfer distances.
fn sweep_matches_single_extractions(scene_out: &Path, data: &Path, result: &serde_json::Value) {
    let run = scene_out.join("plenoxels");
    let gt = data.join("gt_points.ply");
    let mut compared = 0;
    for (key, trim, ply) in [
        ("levels", "off", "plenoxels/points_sigma{}.ply"),
        ("trimmed_levels", "on", "points_sigma{}_trimmed.ply"),
    ] {
        for l in result[key].as_array().unwrap() {
            let Some(chamfer) = l["chamfer_e2"].as_f64() else {
                continue;
            };
            let level = l["level"].as_f64().unwrap();
            let swept = scene_out.join(ply.replace("{}", &level.to_string()));
            let single = scene_out.join(format!("single_{key}_{level}.ply"));
            run_ok(
                bin()
                    .args([
                        "extract",
                        "--backend",
                        "cpu",
                        "--trim-hidden",
                        trim,
                        "--run",
                    ])
                    .arg(&run)
                    .args(["--levels", &level.to_string(), "--out"])
                    .arg(&single),
            );
            assert_eq!(
                std::fs::read(&swept).unwrap(),
                std::fs::read(&single).unwrap(),
                "{key} {level}"
            );
            let (o, _) = run_ok(
                bin()
                    .args(["eval", "--json", "--pred"])
                    .arg(&single)
                    .arg("--gt")
                    .arg(&gt),
            );
            let e: serde_json::Value = serde_json::from_str(o.lines().last().unwrap()).unwrap();
            assert_eq!(e["chamfer_e2"].as_f64().unwrap(), chamfer, "{key} {level}");
            compared += 1;
        }
    }
    assert!(compared >= 4, "only {compared} levels had clouds");
}

#[test]
fn bench_accuracy_needs_a_category_it_can_tell() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("lyre");
    std::fs::create_dir_all(&scene).unwrap();
    let out = bin()
        .args(["bench", "accuracy", "--backend", "cpu", "--data"])
        .arg(&scene)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("lyre") && err.contains("--category"), "{err}");
}
