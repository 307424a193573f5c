//! Stage 2 end to end at a small size: `train --stage all` (stage 1, then αSurf from it) →
//! `extract` of the surfaces → `eval`; `--resume` extends a finished run; a diverging
//! configuration stops with a message and leaves the last good checkpoint intact; `bench surface
//! --json` at a small size reports consistent figures.

use crate::bench_common;

use std::path::{Path, PathBuf};
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_alphasurf"))
}

fn run(cmd: &mut Command) -> (bool, String) {
    let out = cmd.output().expect("spawn alphasurf");
    let text = format!(
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.success(), text)
}

fn run_ok(cmd: &mut Command) -> String {
    let (ok, text) = run(cmd);
    assert!(ok, "{cmd:?} failed:\n{text}");
    text
}

fn scene(dir: &Path) -> PathBuf {
    let data = dir.join("scene");
    run_ok(
        bin()
            .args([
                "make-scene",
                "--kind",
                "thin",
                "--res",
                "48",
                "--views",
                "16",
            ])
            .args(["--spp", "1", "--gt-spacing", "0.02", "--out"])
            .arg(&data),
    );
    data
}

fn metrics(run: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(run.join("metrics.json")).expect("metrics.json");
    serde_json::from_str(&text).expect("valid metrics.json")
}

/// Mean test PSNR of an all-white rendering.
fn white_psnr(data: &Path) -> f64 {
    use alphasurf::data::{view_rays, Dataset, LoadOptions};
    let d = Dataset::load(data, &LoadOptions::default()).unwrap();
    let n = d.test.frames.len();
    (0..n)
        .map(|i| {
            let b = view_rays(&d.test, &d.scene, i);
            let mse = b
                .rgb
                .iter()
                .flatten()
                .map(|&t| ((1.0 - t) as f64).powi(2))
                .sum::<f64>()
                / (3 * b.len()) as f64;
            -10.0 * mse.log10()
        })
        .sum::<f64>()
        / n as f64
}

fn surface_args<'a>(extra: &[&'a str]) -> Vec<&'a str> {
    let mut v = vec!["--backend", "cpu", "--quiet", "--batch", "2048"];
    v.extend_from_slice(extra);
    v
}

#[test]
fn stage_all_extract_eval_and_resume() {
    let dir = tempfile::tempdir().unwrap();
    let data = scene(dir.path());
    let out = dir.path().join("run");
    let text = run_ok(
        bin()
            .args(["train", "--stage", "all", "--data"])
            .arg(&data)
            .arg("--out")
            .arg(&out)
            .args(surface_args(&[
                "--res",
                "48",
                "--iters",
                "300",
                "--surface-iters",
                "120",
                "--checkpoint-every",
                "50",
            ])),
    );
    assert!(text.contains("stage 2 done"), "{text}");
    let m1 = metrics(&out.join("plenoxels"));
    let m2 = metrics(&out.join("surface"));
    assert_eq!(m2["stage"], "surface");
    assert_eq!(m2["config"]["iters"], 120);
    let (p1, p2) = (
        m1["test_psnr"].as_f64().unwrap(),
        m2["test_psnr"].as_f64().unwrap(),
    );
    // Surfaces initialised from stage 1 render the object: well above the all-white image (the
    // initial opacity is low, σα = 0.005·σ, so a short run does not reach stage 1).
    let white = white_psnr(&data);
    assert!(
        p2 > white + 2.0 && p1 > white + 2.0,
        "white {white:.2} dB, stage 1 {p1:.2} dB, stage 2 {p2:.2} dB"
    );
    for key in ["cells", "solves", "hits", "atomic_adds"] {
        assert!(
            m2["per_ray"][key].as_f64().is_some_and(|v| v > 0.0),
            "per_ray.{key} missing or zero"
        );
    }
    let log = std::fs::read_to_string(out.join("surface/train_log.csv")).unwrap();
    assert_eq!(log.lines().count(), 121, "header + one line per step");
    assert!(out.join("surface/test/r_0.png").exists());

    // `render [FLAGS]` of the stage-2 run into `dir/NAME`.
    let render = |name: &str, flags: &[&str]| {
        let mut c = bin();
        c.args(["render", "--backend", "cpu"])
            .args(flags)
            .arg("--run")
            .arg(out.join("surface"))
            .arg("--out")
            .arg(dir.path().join(name));
        run(&mut c)
    };
    // `render` on the stage-2 run draws the test views `train` drew: the same PSNR (same grid,
    // same truncation, same deterministic renderer).
    let renders = dir.path().join("renders");
    let (ok, text) = render("renders", &[]);
    assert!(ok, "{text}");
    let mean = text
        .lines()
        .find_map(|l| l.strip_prefix("mean PSNR "))
        .and_then(|l| l.split(' ').next())
        .and_then(|v| v.parse::<f64>().ok())
        .unwrap_or_else(|| panic!("no mean PSNR in {text}"));
    assert!(
        (mean - p2).abs() < 0.006,
        "render {mean} dB, train {p2:.4} dB"
    );
    assert_eq!(
        std::fs::read(renders.join("r_0.png")).unwrap(),
        std::fs::read(out.join("surface/test/r_0.png")).unwrap()
    );
    // Anti-aliased: 2×2 rays per pixel, another image; 0 is refused.
    let aa = dir.path().join("renders_aa");
    let (ok, text) = render("renders_aa", &["--pixel-samples", "2"]);
    assert!(ok && text.contains("(2×2 rays per pixel)"), "{text}");
    assert_ne!(
        std::fs::read(aa.join("r_0.png")).unwrap(),
        std::fs::read(renders.join("r_0.png")).unwrap()
    );
    let (ok, text) = render("renders_0", &["--pixel-samples", "0"]);
    assert!(!ok && text.contains("--pixel-samples"), "{text}");

    // The αSurf point cloud, then its error against the ground truth.
    let ply = dir.path().join("surface.ply");
    let text = run_ok(
        bin()
            .args(["extract", "--backend", "cpu", "--run"])
            .arg(out.join("surface"))
            .arg("--out")
            .arg(&ply),
    );
    assert!(text.contains("αSurf levels"), "{text}");
    // A thin run trims hidden surfaces by default, with the training cameras of its dataset.
    let hidden = text
        .lines()
        .find(|l| l.starts_with("hidden surfaces:"))
        .unwrap_or_else(|| panic!("no hidden-surface line in {text}"));
    let numbers: Vec<usize> = hidden
        .split(|c: char| !c.is_ascii_digit())
        .filter_map(|w| w.parse().ok())
        .collect();
    // "of C cells …, S seen …, O unseen but open, H hidden …": every cell in one class, most seen.
    let [c, s, o, h] = numbers[..4] else {
        panic!("{hidden}")
    };
    assert!(c > 0 && s + o + h == c && s > c / 2, "{hidden}");
    assert!(text.contains("outermost level:"), "{text}");
    let plain = dir.path().join("plain.ply");
    let text = run_ok(
        bin()
            .args([
                "extract",
                "--backend",
                "cpu",
                "--trim-hidden",
                "off",
                "--run",
            ])
            .arg(out.join("surface"))
            .arg("--out")
            .arg(&plain),
    );
    assert!(!text.contains("hidden surfaces"), "{text}");
    let count = |p: &std::path::Path| {
        let bytes = std::fs::read(p).unwrap();
        let head = String::from_utf8_lossy(&bytes[..bytes.len().min(400)]).to_string();
        head.lines()
            .find_map(|l| l.strip_prefix("element vertex "))
            .and_then(|n| n.trim().parse::<usize>().ok())
            .unwrap()
    };
    assert!(count(&plain) >= count(&ply), "trimming added points");
    // The cameras come from --data when given: a missing dataset is a clear error with `on`.
    let (ok, text) = run(bin()
        .args([
            "extract",
            "--backend",
            "cpu",
            "--trim-hidden",
            "on",
            "--run",
        ])
        .arg(out.join("surface"))
        .args(["--data", "/nonexistent/dataset", "--out"])
        .arg(dir.path().join("y.ply")));
    assert!(
        !ok && text.contains("/nonexistent/dataset") && text.contains("--trim-hidden off"),
        "{text}"
    );
    // With `auto` it is a warning, and every cell is kept.
    let untrimmed = dir.path().join("untrimmed.ply");
    let text = run_ok(
        bin()
            .args(["extract", "--backend", "cpu", "--run"])
            .arg(out.join("surface"))
            .args(["--data", "/nonexistent/dataset", "--out"])
            .arg(&untrimmed),
    );
    assert!(
        text.contains("warning: hidden surfaces not trimmed") && !text.contains("hidden surfaces:"),
        "{text}"
    );
    assert_eq!(count(&untrimmed), count(&plain));
    let text = run_ok(
        bin()
            .args(["eval", "--json", "--pred"])
            .arg(&ply)
            .arg("--gt")
            .arg(data.join("gt_points.ply")),
    );
    let j: serde_json::Value =
        serde_json::from_str(text.lines().rfind(|l| l.starts_with('{')).unwrap()).unwrap();
    let chamfer = j["metrics"]["chamfer"].as_f64().unwrap();
    // A voxel is 3/48 Blender units here and stage 1 had 300 steps: the surfaces lie within
    // about a voxel (misplaced or empty surfaces score ≥ 0.2 on this scene).
    assert!(chamfer > 0.0 && chamfer < 0.1, "Chamfer {chamfer}");
    // --levels is for stage-1 grids only.
    let (ok, text) = run(bin()
        .args(["extract", "--backend", "cpu", "--levels", "50", "--run"])
        .arg(out.join("surface"))
        .arg("--out")
        .arg(dir.path().join("x.ply")));
    assert!(!ok && text.contains("has its own levels"), "{text}");

    // Resume the finished stage-2 run for 10 more steps.
    let text = run_ok(
        bin()
            .args(["train", "--stage", "surface", "--resume", "--data"])
            .arg(&data)
            .arg("--out")
            .arg(out.join("surface"))
            .args(surface_args(&["--surface-iters", "130"])),
    );
    assert!(text.contains("at step 120 of 130"), "{text}");
    assert_eq!(metrics(&out.join("surface"))["config"]["iters"], 130);
}

#[test]
fn diverging_surface_training_stops_and_keeps_the_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let data = scene(dir.path());
    let s1 = dir.path().join("s1");
    run_ok(
        bin()
            .args(["train", "--data"])
            .arg(&data)
            .arg("--out")
            .arg(&s1)
            .args(surface_args(&["--res", "48", "--iters", "200"])),
    );
    let s2 = dir.path().join("s2");
    let base = |extra: &[&str]| {
        let mut c = bin();
        c.args(["train", "--stage", "surface", "--init"])
            .arg(&s1)
            .arg("--data")
            .arg(&data)
            .arg("--out")
            .arg(&s2)
            .args(surface_args(&["--checkpoint-every", "2"]))
            .args(extra);
        c
    };
    // Huge δ steps overflow to ±∞ within a few steps.
    let (ok, text) = run(&mut base(&[
        "--surface-iters",
        "12",
        "--set",
        "lr_delta.init=3e38",
        "--set",
        "lr_delta.last=3e38",
        "--set",
        "lr_delta.delay_steps=0",
    ]));
    assert!(!ok, "diverging run succeeded:\n{text}");
    assert!(text.contains("non-finite"), "{text}");
    // The checkpoint left behind loads and is finite (a stage-2 checkpoint is never written
    // with NaN/Inf).
    let ck = alphasurf::checkpoint::surface::load(&s2.join("surface.npz"));
    if let Ok(ck) = ck {
        assert!(ck.grid.delta.iter().all(|v| v.is_finite()));
    }
    // Bad --set keys and values are errors, not panics.
    for bad in ["nope=1", "lambda_h=\"x\"", "lambda_h"] {
        let (ok, text) = run(&mut base(&["--surface-iters", "1", "--set", bad]));
        assert!(!ok && text.contains("--set"), "{bad}: {text}");
    }
    // --init must exist and hold a stage-1 grid.
    let (ok, text) = run(bin()
        .args(["train", "--stage", "surface", "--init"])
        .arg(dir.path())
        .arg("--data")
        .arg(&data)
        .arg("--out")
        .arg(dir.path().join("s3")));
    assert!(!ok && text.contains("plenoxels.npz"), "{text}");
}

/// `bench surface --json` at 32³: both backends' rays/s and counters, the kernels' device times,
/// where each step's time goes (wall, device, host phases), and the stage-1 figures the ratios
/// are taken against (rounds of stage 1 then stage 2; the reported ratio is the median round's).
#[test]
fn bench_surface_json_is_consistent() {
    let out = run_ok(bin().args([
        "bench",
        "surface",
        "--json",
        "--res",
        "32",
        "--stage1-steps",
        "100",
        "--warm-steps",
        "2",
        "--steps",
        "2",
        "--batch",
        "512",
        "--rounds",
        "3",
    ]));
    let line = out
        .lines()
        .find(|l| l.starts_with('{'))
        .unwrap_or_else(|| panic!("no JSON line:\n{out}"));
    let j: serde_json::Value = serde_json::from_str(line).unwrap();
    let f = |v: &serde_json::Value| v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"));
    let (ok, text) = run(bin().args(["bench", "surface", "--rounds", "2"]));
    assert!(!ok && text.contains("--rounds must be odd"), "{text}");
    let rounds = j["rounds"].as_array().expect("rounds");
    assert_eq!(rounds.len(), 3, "{line}");
    let mut ratios: Vec<f64> = rounds
        .iter()
        .map(|r| {
            let (s1, s2, q) = (
                f(&r["stage1_rays_per_s"]),
                f(&r["surface_rays_per_s"]),
                f(&r["ratio"]),
            );
            assert!(
                s1 > 0.0 && s2 > 0.0 && s1.is_finite() && s2.is_finite(),
                "{r}"
            );
            assert!((q - s2 / s1).abs() <= 1e-9 * q, "{r}");
            q
        })
        .collect();
    ratios.sort_by(f64::total_cmp);
    let stage1 = f(&j["stage1_vulkan_rays_per_s"]);
    assert!(
        (f(&j["ratio_surface_over_stage1_vulkan"]) - ratios[1]).abs() <= 1e-9 * ratios[1],
        "not the median round: {line}"
    );
    for (rate, ratio) in [
        ("vulkan", "ratio_surface_over_stage1_vulkan"),
        (
            "vulkan_data_term_only",
            "ratio_surface_data_term_over_stage1_vulkan",
        ),
    ] {
        let r = f(&j[rate]["rays_per_s"]);
        assert!(r > 0.0 && r.is_finite(), "{rate}: {r}");
        assert!(
            (f(&j[ratio]) - r / stage1).abs() <= 1e-9 * r / stage1,
            "{ratio}"
        );
    }
    for k in ["cells", "solves", "culled", "hits", "blocks_skipped"] {
        let v = f(&j["vulkan"]["per_ray"][k]);
        assert!(v >= 0.0 && v.is_finite(), "{k}: {v}");
    }
    // Both backends train the same batches from the same state: the same hits (up to the
    // near-degenerate rays the parity checks excuse, ≤ 0.5 %).
    let (hv, hc) = (
        f(&j["vulkan"]["per_ray"]["hits"]),
        f(&j["cpu"]["per_ray"]["hits"]),
    );
    assert!((hv - hc).abs() <= 5e-3 * hc.max(1.0), "hits {hv} vs {hc}");
    assert!(f(&j["vulkan"]["per_ray"]["hits"]) > 0.0, "no hits: {line}");
    assert!(f(&j["vulkan"]["device_ms_per_step"]["surface_train"]) > 0.0);
    for (backend, vulkan) in [
        ("vulkan", true),
        ("vulkan_data_term_only", true),
        ("cpu", false),
    ] {
        bench_common::check_step_times(backend, &j[backend], vulkan);
    }
    // The kernels' total is the sum of the per-kernel times.
    let per_kernel: f64 = j["vulkan"]["device_ms_per_step"]
        .as_object()
        .unwrap()
        .values()
        .map(f)
        .sum();
    let total = f(&j["vulkan"]["device_ms_total_per_step"]);
    assert!(
        (per_kernel - total).abs() <= 1e-9 * total,
        "{per_kernel} vs {total}"
    );
}
