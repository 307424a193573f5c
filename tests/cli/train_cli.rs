//! End to end at a small size: make-scene → train (Vulkan and CPU backends) → render → export →
//! import, a run killed with SIGKILL that resumes from its last checkpoint, a run stopped by
//! SIGINT that checkpoints its step and resumes from it (both stages), the scene
//! converted to the COLMAP and IDR layouts training to the same figures; `bench plenoxels --json`
//! at a small size reports consistent figures.

use crate::bench_common;
use crate::data_common::convert::{self, Target};

use alphasurf::checkpoint::format::optim_refs;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_alphasurf"))
}

fn run_ok(cmd: &mut Command) -> String {
    let out = cmd.output().expect("spawn alphasurf");
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{cmd:?} failed:\n{text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    text
}

fn scene(dir: &Path) -> PathBuf {
    scene_of(dir, 32, 12)
}

/// The solid scene in `dir/scene`: `views` training views of `res`² pixels.
fn scene_of(dir: &Path, res: u32, views: u32) -> PathBuf {
    let data = dir.join("scene");
    run_ok(
        bin()
            .args(["make-scene", "--kind", "solid", "--res", &res.to_string()])
            .args(["--views", &views.to_string()])
            .args(["--spp", "1", "--gt-spacing", "0.05", "--out"])
            .arg(&data),
    );
    data
}

fn metrics(run: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(run.join("metrics.json")).expect("metrics.json");
    serde_json::from_str(&text).expect("valid metrics.json")
}

fn train(data: &Path, out: &Path, backend: &str, extra: &[&str]) -> String {
    run_ok(
        bin()
            .args(["train", "--data"])
            .arg(data)
            .arg("--out")
            .arg(out)
            .args([
                "--backend",
                backend,
                "--res",
                "32",
                "--batch",
                "2048",
                "--quiet",
            ])
            .args(extra),
    )
}

/// Runs `render` and returns the mean PSNR it prints.
fn render_mean_psnr(cmd: &mut std::process::Command) -> f64 {
    run_ok(cmd)
        .lines()
        .find_map(|l| l.strip_prefix("mean PSNR "))
        .and_then(|l| l.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .expect("mean PSNR line")
}

#[test]
fn train_render_export_import_on_both_backends() {
    let dir = tempfile::tempdir().unwrap();
    let data = scene(dir.path());
    let (rv, rc) = (dir.path().join("vk"), dir.path().join("cpu"));
    train(&data, &rv, "vulkan", &["--iters", "60"]);
    train(&data, &rc, "cpu", &["--iters", "60"]);
    let (mv, mc) = (metrics(&rv), metrics(&rc));
    let (pv, pc) = (
        mv["test_psnr"].as_f64().unwrap(),
        mc["test_psnr"].as_f64().unwrap(),
    );
    // The white background alone scores well below this on the solid scene.
    assert!(pv > 15.0, "Vulkan test PSNR {pv}");
    // Float atomics add in a different order on every run, and 60 steps at σ's learning rate of
    // 30 amplify any early difference. Measured on this set-up: Vulkan alone 0 of 20 runs off
    // the CPU's 23.429 dB, three processes at once on 2 cores 2 of 30 off, both (and an earlier
    // one) at exactly 23.082 dB, their batch MSE leaving the others' 1e-9 spread at step 5; the
    // CPU three at once 0 of 30. One binary decision flips (most likely a float threshold under
    // another atomic order; a race is not excluded). The bound leaves room for that, not for a
    // wrong step.
    assert!(
        (pv - pc).abs() <= 1.0,
        "backends differ: vulkan {pv:.3} dB, cpu {pc:.3} dB"
    );
    for key in ["train_rays_per_s", "peak_rss_bytes", "bytes_per_vertex"] {
        assert!(
            mv[key].as_f64().is_some_and(|v| v > 0.0),
            "metrics.json lacks {key}"
        );
    }
    assert_eq!(mv["config"]["iters"], 60);
    assert!(rv.join("test/r_0.png").exists());

    // render reproduces the training run's test PSNR.
    let mean = render_mean_psnr(
        bin()
            .args(["render", "--run"])
            .arg(&rv)
            .arg("--out")
            .arg(dir.path().join("r")),
    );
    assert!((mean - pv).abs() < 0.01, "render {mean} vs train {pv}");

    // A run trained on downscaled images renders (and scores) at that size.
    let rd = dir.path().join("half");
    train(&data, &rd, "cpu", &["--iters", "20", "--downscale", "2"]);
    let pd = metrics(&rd)["test_psnr"].as_f64().unwrap();
    let mean_half = render_mean_psnr(
        bin()
            .args(["render", "--backend", "cpu", "--run"])
            .arg(&rd)
            .arg("--out")
            .arg(dir.path().join("rh")),
    );
    assert!(
        (mean_half - pd).abs() < 0.01,
        "render {mean_half} vs train {pd} at downscale 2"
    );
    let full = image::image_dimensions(rv.join("test/r_0.png")).unwrap();
    let half = image::image_dimensions(dir.path().join("rh/r_0.png")).unwrap();
    assert_eq!(half, (full.0 / 2, full.1 / 2));

    // export → import round trip renders the same.
    let ck = dir.path().join("ckpt.npz");
    run_ok(
        bin()
            .args(["export", "--run"])
            .arg(&rv)
            .arg("--out")
            .arg(&ck),
    );
    let imported = dir.path().join("imported");
    run_ok(
        bin()
            .args(["import", "--ckpt"])
            .arg(&ck)
            .arg("--data")
            .arg(&data)
            .arg("--out")
            .arg(&imported),
    );
    let out = run_ok(
        bin()
            .args(["render", "--run"])
            .arg(&imported)
            .arg("--out")
            .arg(dir.path().join("r2")),
    );
    assert!(out.contains(&format!("mean PSNR {mean:.2}")), "{out}");
}

#[test]
fn sigkill_loses_at_most_the_steps_since_the_last_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let data = scene(dir.path());
    let run = dir.path().join("run");
    let mut child = bin()
        .args(["train", "--data"])
        .arg(&data)
        .arg("--out")
        .arg(&run)
        .args([
            "--backend",
            "cpu",
            "--res",
            "32",
            "--batch",
            "1024",
            "--quiet",
        ])
        .args(["--iters", "100000", "--checkpoint-every", "5"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let ckpt = run.join("plenoxels.npz");
    let start = Instant::now();
    while !ckpt.exists() {
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no checkpoint after 120 s"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    // Let a few more checkpoints go by, then kill without warning (possibly mid-write).
    std::thread::sleep(Duration::from_millis(1500));
    child.kill().unwrap();
    child.wait().unwrap();
    let ck = alphasurf::checkpoint::format::load(&ckpt).expect("checkpoint intact after SIGKILL");
    let step = ck.meta["step"].as_u64().unwrap();
    assert!(
        step >= 5 && step.is_multiple_of(5),
        "checkpoint at step {step}"
    );
    // Resume with a schedule that ends soon after the checkpoint.
    let mut cfg = ck.meta["config"].clone();
    cfg["iters"] = serde_json::json!(step + 10);
    let meta = serde_json::json!({ "stage": "plenoxels", "step": step, "config": cfg });
    alphasurf::checkpoint::format::save(&ckpt, &ck.grid, &optim_refs(&ck.optim), &meta).unwrap();
    let out = run_ok(
        bin()
            .args(["train", "--data"])
            .arg(&data)
            .arg("--out")
            .arg(&run)
            .args(["--backend", "cpu", "--resume", "--quiet"]),
    );
    assert!(out.contains("stage 1 done"), "{out}");
    let m = metrics(&run);
    assert_eq!(m["config"]["iters"].as_u64().unwrap(), step + 10);
    let done = alphasurf::checkpoint::format::load(&ckpt).unwrap();
    assert_eq!(done.meta["step"].as_u64().unwrap(), step + 10);
    // The log was cut back to the checkpoint: every step once, no torn row (issue 24).
    let log = std::fs::read_to_string(run.join("train_log.csv")).unwrap();
    let steps: Vec<u64> = log
        .lines()
        .skip(1)
        .map(|l| {
            assert_eq!(l.split(',').count(), 4, "malformed row {l:?}");
            l.split(',').next().unwrap().parse().unwrap()
        })
        .collect();
    assert_eq!(steps, (1..=step + 10).collect::<Vec<_>>());
}

/// Starts a training `cmd` (flags for a run far longer than the test), waits until its training
/// loop runs (`log` exists: the loop opens it after catching signals) and a little more, sends
/// SIGINT, and returns the exit code and the step the message says the checkpoint holds.
fn stop_with_sigint(cmd: &mut Command, log: &Path) -> (Option<i32>, u64, String) {
    let mut child = cmd
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while !log.exists() {
        if child.try_wait().unwrap().is_some() {
            let out = child.wait_with_output().unwrap();
            panic!(
                "ended before training: {}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no training log after 120 s"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(500));
    // SAFETY: kill(2) on our own child's pid.
    assert_eq!(
        unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGINT) },
        0
    );
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    let step = err
        .split("after step ")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no stop message: {err}"));
    (out.status.code(), step, err)
}

/// The steps of a training log's rows, each checked for its column count.
fn log_steps(run: &Path, columns: usize) -> Vec<u64> {
    let log = std::fs::read_to_string(run.join("train_log.csv")).unwrap();
    log.lines()
        .skip(1)
        .map(|l| {
            assert_eq!(l.split(',').count(), columns, "malformed row {l:?}");
            l.split(',').next().unwrap().parse().unwrap()
        })
        .collect()
}

#[test]
fn sigint_checkpoints_the_step_it_stops_at_and_resume_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let (data, s1) = stage1_run(dir.path(), &["--iters", "20"]);
    let train_args = |out: &Path, extra: &[&str]| {
        let mut c = bin();
        c.args(["train", "--data"]).arg(&data).arg("--out").arg(out);
        c.args(["--backend", "cpu", "--batch", "1024", "--quiet"]);
        c.args(extra);
        c
    };
    // Stage 1 (no periodic checkpoint: the one on disk is the stop's), then stage 2.
    let run = dir.path().join("stopped1");
    let (code, step, err) = stop_with_sigint(
        &mut train_args(
            &run,
            &[
                "--res",
                "32",
                "--iters",
                "1000000",
                "--checkpoint-every",
                "1000000",
            ],
        ),
        &run.join("train_log.csv"),
    );
    assert_eq!(code, Some(130), "{err}");
    assert!(
        err.contains("plenoxels.npz") && err.contains("--resume"),
        "{err}"
    );
    let ck = alphasurf::checkpoint::format::load(&run.join("plenoxels.npz")).unwrap();
    assert_eq!(ck.meta["step"].as_u64(), Some(step));
    assert!(step > 0 && step < 1_000_000, "{err}");
    assert_eq!(log_steps(&run, 4), (1..=step).collect::<Vec<_>>());
    let more = (step + 10).to_string();
    let out = run_ok(&mut train_args(
        &run,
        &["--res", "32", "--resume", "--iters", &more],
    ));
    assert!(out.contains("stage 1 done"), "{out}");
    assert_eq!(log_steps(&run, 4), (1..=step + 10).collect::<Vec<_>>());

    let run = dir.path().join("stopped2");
    let surface = |extra: &[&str]| {
        let mut c = train_args(&run, &["--stage", "surface", "--init"]);
        c.arg(&s1).args(["--category", "synthetic"]).args(extra);
        c
    };
    let (code, step, err) = stop_with_sigint(
        &mut surface(&[
            "--surface-iters",
            "1000000",
            "--checkpoint-every",
            "1000000",
        ]),
        &run.join("train_log.csv"),
    );
    assert_eq!(code, Some(130), "{err}");
    assert!(err.contains("surface.npz"), "{err}");
    assert!(step > 0 && step < 1_000_000, "{err}");
    assert_eq!(log_steps(&run, 7), (1..=step).collect::<Vec<_>>());
    let more = (step + 10).to_string();
    run_ok(&mut surface(&["--resume", "--surface-iters", &more]));
    assert_eq!(metrics(&run)["config"]["iters"].as_u64(), Some(step + 10));
    assert_eq!(log_steps(&run, 7), (1..=step + 10).collect::<Vec<_>>());
}

#[test]
fn non_finite_training_state_stops_the_run_and_keeps_the_last_checkpoint() {
    use alphasurf::data::{Dataset, LoadOptions};
    use alphasurf::plenoxel::CpuPlenoxels;
    use alphasurf::stage::StageBackend;
    use alphasurf::train::{plenoxels_steps, PlenoxelsConfig};
    let dir = tempfile::tempdir().unwrap();
    let data = Dataset::load(&scene(dir.path()), &LoadOptions::default()).unwrap();
    let mut cfg = PlenoxelsConfig::fast();
    (
        cfg.res,
        cfg.upsample,
        cfg.iters,
        cfg.batch,
        cfg.checkpoint_every,
        cfg.checkpoint_min_seconds,
    ) = (16, vec![], 4, 512, 2, 0.0);
    let run = dir.path().join("run");
    let grid = alphasurf::grid::Grid::sphere(16, [0.0; 3], [1.0; 3], 1.0, cfg.init_sigma);
    let mut b = CpuPlenoxels::new(grid);
    plenoxels_steps::train(&mut b, &data, &cfg, &run, 0, false).unwrap();
    let good = std::fs::read(alphasurf::checkpoint::path::<
        alphasurf::plenoxel::PlenoxelsStage,
    >(&run))
    .unwrap();
    // Poison the grid: every σ becomes NaN, so the next step's loss is NaN.
    let mut poisoned = b.grid().unwrap();
    poisoned.density.iter_mut().for_each(|v| *v = f32::NAN);
    b.load(poisoned, None).unwrap();
    cfg.iters = 8;
    let err = plenoxels_steps::train(&mut b, &data, &cfg, &run, 4, false).unwrap_err();
    let msg = format!("{err:#}");
    assert!(msg.contains("non-finite"), "{msg}");
    assert_eq!(
        std::fs::read(alphasurf::checkpoint::path::<
            alphasurf::plenoxel::PlenoxelsStage,
        >(&run))
        .unwrap(),
        good,
        "checkpoint overwritten"
    );
}

/// `train --stage all` on the built-in scene converted to COLMAP (text, binary) and IDR gives the
/// same stage-1 and stage-2 test PSNR (within 0.05 dB) and the same extracted
/// cloud's Chamfer within 1 %. The CPU backend is deterministic run to run (see above), so the
/// only difference is f32 rounding in the converted poses (≤ 5e-7); measured: 3e-5 dB, 2e-6 dB
/// and 0.01 %. A wrong axis convention, principal point or scene box costs whole dB.
/// Converted to instant-ngp's `transforms.json` with its images distorted by a phone's OPENCV
/// lens (undistorted on load), and to LLFF's `poses_bounds.npy`, and trained in the original's box
/// (`--box`, recorded in run.json), the test PSNR of both stages stays within 1 dB of the
/// original's (measured: instant-ngp +0.21 / +0.12 dB).
#[test]
fn converted_layouts_train_to_the_same_figures() {
    let dir = tempfile::tempdir().unwrap();
    let data = scene(dir.path());
    let gt = data.join("gt_points.ply");
    let figures = |ds: &Path, name: &str, extra: &[&str]| -> [f64; 3] {
        let out = dir.path().join(format!("run-{name}"));
        train(
            ds,
            &out,
            "cpu",
            &[
                &["--stage", "all", "--iters", "60", "--surface-iters", "60"],
                extra,
            ]
            .concat(),
        );
        let pts = dir.path().join(format!("{name}.ply"));
        run_ok(
            bin()
                .args(["extract", "--backend", "cpu", "--run"])
                .arg(out.join("surface"))
                .arg("--out")
                .arg(&pts),
        );
        let eval = run_ok(
            bin()
                .args(["eval", "--json", "--pred"])
                .arg(&pts)
                .arg("--gt")
                .arg(&gt),
        );
        let e: serde_json::Value = serde_json::from_str(eval.lines().last().unwrap()).unwrap();
        [
            metrics(&out.join("plenoxels"))["test_psnr"]
                .as_f64()
                .unwrap(),
            metrics(&out.join("surface"))["test_psnr"].as_f64().unwrap(),
            e["chamfer_e2"].as_f64().unwrap(),
        ]
    };
    let want = figures(&data, "original", &[]);
    for target in [Target::ColmapText, Target::ColmapBinary, Target::Idr] {
        let copy = dir.path().join(format!("{target:?}"));
        convert::convert(&data, &copy, target).unwrap();
        let got = figures(&copy, &format!("{target:?}"), &[]);
        assert!(
            (got[0] - want[0]).abs() <= 0.05 && (got[1] - want[1]).abs() <= 0.05,
            "{target:?}: test PSNR {got:?} vs the original's {want:?}"
        );
        assert!(
            (got[2] - want[2]).abs() <= 0.01 * want[2],
            "{target:?}: Chamfer {} vs {}",
            got[2],
            want[2]
        );
    }
    let cube = "-1.5,-1.5,-1.5,1.5,1.5,1.5";
    for (name, target) in [
        ("instant-ngp", Target::InstantNgp(convert::PHONE_LENS)),
        ("llff", Target::Llff),
    ] {
        let copy = dir.path().join(name);
        convert::convert(&data, &copy, target).unwrap();
        let got = figures(&copy, name, &["--box", cube]);
        eprintln!("{name}: {got:?}, original {want:?}");
        assert!(
            (got[0] - want[0]).abs() <= 1.0 && (got[1] - want[1]).abs() <= 1.0,
            "{name}: test PSNR {got:?} vs the original's {want:?}"
        );
    }
    let info: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("run-instant-ngp/surface/run.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(
        info["scene_box"],
        serde_json::json!({"min": [-1.5, -1.5, -1.5], "max": [1.5, 1.5, 1.5]}),
        "{info}"
    );
}

/// A stage-1 run of `scene` in `dir/run` with `extra` flags: the dataset and the run.
fn stage1_run(dir: &Path, extra: &[&str]) -> (PathBuf, PathBuf) {
    let data = scene(dir);
    let run = dir.join("run");
    train(
        &data,
        &run,
        "cpu",
        &[&["--stage", "plenoxels"], extra].concat(),
    );
    (data, run)
}

#[test]
fn plenoxels_set_reaches_the_run_and_resume_refuses_it() {
    let dir = tempfile::tempdir().unwrap();
    let (data, run) = stage1_run(
        dir.path(),
        &["--iters", "20", "--plenoxels-set", "tv_sh=0.0025"],
    );
    let cfg = &metrics(&run)["config"];
    assert_eq!(
        cfg["tv_sh"].as_f64().map(|v| v as f32),
        Some(0.0025),
        "{cfg}"
    );
    let out = bin()
        .args(["train", "--resume", "--backend", "cpu", "--data"])
        .arg(&data)
        .arg("--out")
        .arg(&run)
        .args(["--iters", "30", "--plenoxels-set", "tv_sh=0"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("--plenoxels-set"),
        "{err}"
    );
}

/// A run records the scene box's scale it trained with in `run.json`, and `extract` writes its
/// points back in dataset units with it (COLMAP and IDR boxes have their own scale; the
/// NeRF-synthetic box's 2/3 was assumed before): halving the recorded scale doubles every point,
/// and `--scene-scale` still overrides it.
#[test]
fn extract_uses_the_scene_scale_the_run_recorded() {
    let dir = tempfile::tempdir().unwrap();
    let (_, run) = stage1_run(dir.path(), &["--iters", "40"]);
    let marker = run.join("run.json");
    let mut info: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&marker).unwrap()).unwrap();
    let recorded = info["scene_scale"]
        .as_f64()
        .expect("run.json records scene_scale");
    assert!(
        (recorded - 2.0 / 3.0).abs() < 1e-6,
        "scene_scale {recorded}"
    );
    let extract = |name: &str, extra: &[&str]| {
        let out = dir.path().join(name);
        run_ok(
            bin()
                .args(["extract", "--backend", "cpu", "--levels", "10", "--run"])
                .arg(&run)
                .arg("--out")
                .arg(&out)
                .args(extra),
        );
        alphasurf::io::ply::read_points(&out).unwrap()
    };
    let before = extract("a.ply", &[]);
    info["scene_scale"] = serde_json::json!(recorded / 2.0);
    std::fs::write(&marker, serde_json::to_string(&info).unwrap()).unwrap();
    let halved = extract("b.ply", &["--thin-radius", "0.002"]);
    let overridden = extract("c.ply", &["--scene-scale", &recorded.to_string()]);
    assert!(!before.is_empty());
    assert_eq!(
        overridden, before,
        "--scene-scale overrides the recorded scale"
    );
    assert_eq!(
        halved.len(),
        before.len(),
        "thinning radius doubled with the units"
    );
    for (h, b) in halved.iter().zip(&before) {
        for k in 0..3 {
            assert!(
                (h[k] - 2.0 * b[k]).abs() <= 1e-5 * (1.0 + b[k].abs()),
                "{h:?} vs 2×{b:?}"
            );
        }
    }
}

/// `bench plenoxels --json` at 32³ with every transfer forced through staging, as on a discrete
/// GPU (the step's own uploads and readbacks need none): both backends train the same batches from
/// the same grid (the same counters up to the near-degenerate samples the parity checks excuse,
/// ≤ 0.5 %: samples shaded, walked past — evaluated empty or skipped, split by each backend's
/// occupancy blocks — and atomic adds; MSE within 1e-5 relative, float atomics summing in another
/// order), and report where each step's time goes (wall, device, host phases).
#[test]
fn bench_plenoxels_json_reports_where_the_time_goes() {
    let out = run_ok(bin().env("ALPHASURF_FORCE_STAGING", "1").args([
        "bench",
        "plenoxels",
        "--json",
        "--res",
        "32",
        "--warm-steps",
        "12",
        "--steps",
        "2",
        "--batch",
        "256",
    ]));
    let line = out
        .lines()
        .find(|l| l.starts_with('{'))
        .unwrap_or_else(|| panic!("no JSON line:\n{out}"));
    let j: serde_json::Value = serde_json::from_str(line).unwrap();
    let f = |v: &serde_json::Value| v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"));
    for (backend, vulkan) in [("vulkan", true), ("cpu", false)] {
        assert!(f(&j[backend]["rays_per_s"]) > 0.0, "{line}");
        bench_common::check_step_times(backend, &j[backend], vulkan);
    }
    let per_ray = |backend: &str, k: &str| match k {
        "walked" => f(&j[backend]["per_ray"]["empty"]) + f(&j[backend]["per_ray"]["skipped"]),
        _ => f(&j[backend]["per_ray"][k]),
    };
    for k in ["shaded", "walked", "atomic_adds"] {
        let (v, c) = (per_ray("vulkan", k), per_ray("cpu", k));
        assert!(
            (v - c).abs() <= 5e-3 * c.max(1.0),
            "per ray {k}: {v} vs {c}"
        );
    }
    let (mv, mc) = (f(&j["vulkan"]["mean_mse"]), f(&j["cpu"]["mean_mse"]));
    assert!((mv - mc).abs() <= 1e-5 * mc, "mse {mv} vs {mc}");
    assert!(
        f(&j["device_ms_per_step"]["plenoxel_train"]) > 0.0,
        "{line}"
    );
}

/// Mean colour (0..1) of the `k`×`k` corner block of an image (the built-in scenes' cameras
/// look at the object: their corners see the background).
fn corner(img: &image::RgbaImage, k: u32) -> [f64; 3] {
    let mut acc = [0.0; 3];
    for y in 0..k {
        for x in 0..k {
            let p = img.get_pixel(x, y).0;
            for c in 0..3 {
                acc[c] += p[c] as f64 / 255.0 / (k * k) as f64;
            }
        }
    }
    acc
}

#[test]
fn black_background_trains_and_renders_on_black() {
    use alphasurf::data::{BackgroundMode, Dataset, LoadOptions};
    let dir = tempfile::tempdir().unwrap();
    let data = scene(dir.path());
    // The targets: alpha composited on black, not white.
    for (mode, want) in [(BackgroundMode::Black, 0.0), (BackgroundMode::White, 1.0)] {
        let d = Dataset::load(
            &data,
            &LoadOptions {
                background: mode,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(d.background, mode);
        let f = &d.test.frames[0].image;
        assert!(f.had_alpha && f.alpha(0, 0) == 0.0, "corner not background");
        assert_eq!(f.rgb(0, 0), [want; 3], "{mode:?} target corner");
    }
    let run = dir.path().join("run");
    train(
        &data,
        &run,
        "vulkan",
        &["--iters", "60", "--background", "black"],
    );
    let m = metrics(&run);
    let psnr = m["test_psnr"].as_f64().unwrap();
    // As the white run's bound (train_render_export_import_on_both_backends).
    assert!(psnr > 15.0, "test PSNR {psnr}");
    assert_eq!(m["background"]["mode"], "black");
    assert_eq!(m["background"]["rgb"], serde_json::json!([0.0, 0.0, 0.0]));
    let info: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("run.json")).unwrap()).unwrap();
    assert_eq!(info["background"], "black");
    let ck = alphasurf::checkpoint::format::load(&run.join("plenoxels.npz")).unwrap();
    assert_eq!(ck.meta["background"]["mode"], "black");
    // The test renders: background corners near black (0.05: the empty space of a 60-step grid
    // still holds a little density).
    let img = image::open(run.join("test/r_0.png")).unwrap().to_rgba8();
    let c = corner(&img, 4);
    eprintln!("black: test PSNR {psnr:.3} dB, render corner {c:?}");
    assert!(c.iter().all(|&v| v < 0.05), "render corner {c:?}");
    // `render` composites the data and the views on the run's background: the same PSNR.
    let mean = render_mean_psnr(
        bin()
            .args(["render", "--run"])
            .arg(&run)
            .arg("--out")
            .arg(dir.path().join("r")),
    );
    assert!((mean - psnr).abs() < 0.01, "render {mean} vs train {psnr}");
    // Resuming under another background is refused, naming both.
    let resume = |extra: &[&str]| {
        bin()
            .args(["train", "--data"])
            .arg(&data)
            .arg("--out")
            .arg(&run)
            .args(["--backend", "cpu", "--resume", "--iters", "70", "--quiet"])
            .args(extra)
            .output()
            .unwrap()
    };
    let out = resume(&["--background", "white"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "resumed on white");
    assert!(
        err.contains("--background white") && err.contains("--background black"),
        "{err}"
    );
    // Without --background (auto) the run goes on with its own.
    let out = resume(&[]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(metrics(&run)["background"]["mode"], "black");
}

#[test]
fn learned_background_converges_to_the_backdrop_of_images_without_alpha() {
    let dir = tempfile::tempdir().unwrap();
    let data = scene(dir.path());
    // With alpha the colour is known: learned refuses it, naming the dataset and the option.
    let out = bin()
        .args(["train", "--data"])
        .arg(&data)
        .arg("--out")
        .arg(dir.path().join("refused"))
        .args(["--backend", "cpu", "--background", "learned", "--quiet"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains(&data.display().to_string()) && err.contains("--background learned"),
        "{err}"
    );
    let backdrop = [0.2f32, 0.6, 0.9];
    drop_alpha(&data, backdrop);
    let run = dir.path().join("run");
    train(
        &data,
        &run,
        "vulkan",
        &[
            "--stage",
            "all",
            "--iters",
            "200",
            "--surface-iters",
            "40",
            "--background",
            "learned",
        ],
    );
    let rgb = |m: &serde_json::Value| -> Vec<f64> {
        assert_eq!(m["background"]["mode"], "learned");
        (0..3)
            .map(|c| m["background"]["rgb"][c].as_f64().unwrap())
            .collect()
    };
    let (s1, s2) = (
        metrics(&run.join("plenoxels")),
        metrics(&run.join("surface")),
    );
    // The colour starts at the images' border median (here the backdrop, to 8 bits) and stays
    // within a few RMSProp steps (the SH rate, 1e-2 here) of it: 0.03 allows three.
    for (name, m) in [("stage 1", &s1), ("stage 2", &s2)] {
        let got = rgb(m);
        eprintln!("{name}: learned {got:?}, backdrop {backdrop:?}");
        for c in 0..3 {
            assert!(
                (got[c] - backdrop[c] as f64).abs() <= 0.03,
                "{name} learned {got:?}, backdrop {backdrop:?}"
            );
        }
    }
    let s1_path = run.join("plenoxels/plenoxels.npz");
    let s1_ck = alphasurf::checkpoint::format::load(&s1_path).unwrap();
    assert_eq!(s1_ck.meta["background"]["rgb"], s1["background"]["rgb"]);
    // Resume and stage 2 start from the checkpoint's colour: set it to grey, far from the
    // backdrop and from the images' border median.
    let mut meta = s1_ck.meta.clone();
    meta["background"]["rgb"] = serde_json::json!([0.5, 0.5, 0.5]);
    alphasurf::checkpoint::format::save(&s1_path, &s1_ck.grid, &optim_refs(&s1_ck.optim), &meta)
        .unwrap();
    let (b, _, _, rec) = alphasurf::checkpoint::resume::<
        alphasurf::plenoxel::PlenoxelsStage,
        alphasurf::train::PlenoxelsConfig,
        _,
    >(cpu_plenoxels, &s1_path)
    .unwrap();
    use alphasurf::stage::StageBackend;
    let restored = b.background().unwrap();
    assert!(restored.learned() && restored.rgb == [0.5; 3] && restored == rec.kernel());
    let s2b = dir.path().join("s2b");
    run_ok(
        bin()
            .args(["train", "--stage", "surface", "--init"])
            .arg(run.join("plenoxels"))
            .arg("--data")
            .arg(&data)
            .arg("--out")
            .arg(&s2b)
            .args(["--backend", "cpu", "--background", "learned", "--quiet"])
            .args(["--surface-iters", "1", "--batch", "256"]),
    );
    // One RMSProp step moves a channel by at most lr/√(1 − β) (stage 2's SH rate, ≤ 3e-3 in the
    // presets, β 0.95: ≤ 0.014); started from the border median it would sit 0.3 or more away.
    let one = rgb(&metrics(&s2b));
    assert!(
        one.iter().all(|&c| (c - 0.5).abs() <= 0.05),
        "stage 2 did not start from stage 1's colour: {one:?}"
    );
    let psnr = s1["test_psnr"].as_f64().unwrap();
    eprintln!(
        "learned: stage-1 test PSNR {psnr:.3} dB, stage-2 {:.3} dB",
        s2["test_psnr"].as_f64().unwrap()
    );
    // Measured 26.5 dB; a fixed white background on the RGBA scene gives 23.0 dB at 200 steps.
    assert!(psnr > 20.0, "stage-1 test PSNR {psnr}");
}

/// Replace the scene's RGBA images by RGB ones composited on `backdrop` (photos without masks).
fn drop_alpha(data: &Path, backdrop: [f32; 3]) {
    for split in ["train", "val", "test"] {
        for e in std::fs::read_dir(data.join(split)).unwrap() {
            let path = e.unwrap().path();
            if path.extension().is_none_or(|x| x != "png") {
                continue;
            }
            let rgba = image::open(&path).unwrap().to_rgba8();
            let rgb = image::RgbImage::from_fn(rgba.width(), rgba.height(), |x, y| {
                let p = rgba.get_pixel(x, y).0;
                let a = p[3] as f32 / 255.0;
                image::Rgb(std::array::from_fn(|c| {
                    ((p[c] as f32 / 255.0 * a + (1.0 - a) * backdrop[c]) * 255.0).round() as u8
                }))
            });
            rgb.save(&path).unwrap();
        }
    }
}

#[test]
fn learned_background_converges_from_grey_on_the_device() {
    use alphasurf::abi::buffers::Background;
    use alphasurf::data::{BackgroundMode, Dataset, LoadOptions, TrainViews};
    use alphasurf::grid::Grid;
    use alphasurf::plenoxel::VulkanPlenoxels;
    use alphasurf::stage::StageBackend;
    use alphasurf::train::PlenoxelsConfig;
    let dir = tempfile::tempdir().unwrap();
    let data = scene(dir.path());
    let backdrop = [0.2f32, 0.6, 0.9];
    drop_alpha(&data, backdrop);
    let d = Dataset::load(
        &data,
        &LoadOptions {
            background: BackgroundMode::Learned,
            ..Default::default()
        },
    )
    .unwrap();
    let b = d.train.border_median();
    assert!(
        // The images hold the backdrop rounded to 8 bits.
        (0..3).all(|c| (b[c] - backdrop[c]).abs() <= 1.0 / 255.0),
        "border median {b:?}"
    );
    // From mid grey instead of the border median: the optimiser alone must find the backdrop.
    let cfg = PlenoxelsConfig::fast();
    let gpu = alphasurf::gpu::test_gpu();
    let grid = Grid::sphere(32, [0.0; 3], [d.scene.radius; 3], 1.0, cfg.init_sigma);
    let mut vk = VulkanPlenoxels::new(gpu, grid).unwrap();
    vk.set_background(Background::new([0.5; 3], true)).unwrap();
    let views = TrainViews::new(&d.train, &d.scene).unwrap();
    for step in 0..200 {
        let p = cfg.step_params(step, None);
        vk.step_sampled(&views, 3 + step as u64, 2048, &p).unwrap();
    }
    let bg = vk.background().unwrap();
    eprintln!(
        "from grey after 200 steps: {:?}, backdrop {backdrop:?}",
        bg.rgb
    );
    // 0.3 to 0.4 away at the start; RMSProp moves it by about its rate (1e-2) per step, so 200
    // steps leave it within a few steps' jitter: 0.03 allows three.
    for c in 0..3 {
        assert!(
            (bg.rgb[c] - backdrop[c]).abs() <= 0.03,
            "learned {:?}, backdrop {backdrop:?}",
            bg.rgb
        );
    }
    assert!(bg.learned() && bg.grad == [0.0; 3], "{bg:?}");
}

#[test]
fn unknown_background_is_a_usage_error() {
    let dir = tempfile::tempdir().unwrap();
    let out = bin()
        .args(["train", "--data"])
        .arg(dir.path())
        .arg("--out")
        .arg(dir.path().join("run"))
        .args(["--background", "pink"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("invalid value 'pink'") && err.contains("white, black, learned"),
        "{err}"
    );
}

/// `train --box` sets the grid's cube, which run.json records; stage 2 from that run takes it
/// without the flag, and `--resume` with another box is refused (a grid is only valid in the box
/// it was trained in).
#[test]
fn the_scene_box_travels_with_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let (data, run) = stage1_run(dir.path(), &["--iters", "20", "--box", "-1,-1,-1,1,1,1"]);
    let recorded = |run: &Path| -> serde_json::Value {
        let text = std::fs::read_to_string(run.join("run.json")).unwrap();
        serde_json::from_str::<serde_json::Value>(&text).unwrap()["scene_box"].clone()
    };
    let unit = serde_json::json!({"min": [-1.0, -1.0, -1.0], "max": [1.0, 1.0, 1.0]});
    assert_eq!(recorded(&run), unit);
    let s2 = dir.path().join("s2");
    run_ok(
        bin()
            .args(["train", "--stage", "surface", "--backend", "cpu", "--quiet"])
            .args(["--iters", "10", "--batch", "2048", "--data"])
            .arg(&data)
            .arg("--init")
            .arg(&run)
            .arg("--out")
            .arg(&s2),
    );
    assert_eq!(recorded(&s2), unit, "stage 2 trains in stage 1's box");
    let out = bin()
        .args(["train", "--resume", "--backend", "cpu", "--data"])
        .arg(&data)
        .arg("--out")
        .arg(&run)
        .args(["--iters", "30", "--box", "-2,-2,-2,2,2,2"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("--box") && err.contains("trained in"),
        "{err}"
    );
}

/// Replace the scene's RGBA images by RGB ones composited on a backdrop that varies with the
/// ray's direction: a distant environment, which spheres can hold and one colour cannot.
fn drop_alpha_on_environment(data: &Path) {
    use alphasurf::data::{Dataset, LoadOptions};
    let env = |d: glam::Vec3| [0.5 + 0.4 * d.x, 0.5 + 0.4 * d.y, 0.5 + 0.3 * d.z];
    let d = Dataset::load(data, &LoadOptions::default()).unwrap();
    for f in d
        .train
        .frames
        .iter()
        .chain(&d.val().frames)
        .chain(&d.test.frames)
    {
        let rgba = image::open(&f.file).unwrap().to_rgba8();
        let rgb = image::RgbImage::from_fn(rgba.width(), rgba.height(), |x, y| {
            let p = rgba.get_pixel(x, y).0;
            let a = p[3] as f32 / 255.0;
            let e = env(f.camera.pixel_ray(x, y).1);
            image::Rgb(std::array::from_fn(|c| {
                ((p[c] as f32 / 255.0 * a + (1.0 - a) * e[c]) * 255.0).round() as u8
            }))
        });
        rgb.save(&f.file).unwrap();
    }
}

/// `--background spheres`: stage 1 learns an environment one colour cannot hold, its checkpoint
/// keeps the spheres (resume restores them bit for bit), stage 2 and `render` composite on them.
#[test]
fn background_spheres_learn_the_environment_and_travel_with_the_run() {
    let dir = tempfile::tempdir().unwrap();
    // Enough rays to reach the spheres' texels the test views see (40 views of 64² pixels: 160k
    // pixels for 16 maps of 32² texels; the `scene` helper's 12 of 32² leave most unseen).
    let data = scene_of(dir.path(), 64, 40);
    drop_alpha_on_environment(&data);
    let stage1 = |name: &str, background: &str| {
        let run = dir.path().join(name);
        train(
            &data,
            &run,
            "cpu",
            &[
                "--stage",
                "plenoxels",
                "--iters",
                "300",
                "--background",
                background,
            ],
        );
        run
    };
    let (colour, spheres) = (stage1("learned", "learned"), stage1("spheres", "spheres"));
    let psnr = |run: &Path| metrics(run)["test_psnr"].as_f64().unwrap();
    let (p_colour, p_spheres) = (psnr(&colour), psnr(&spheres));
    eprintln!("stage-1 test PSNR: one learned colour {p_colour:.2} dB, spheres {p_spheres:.2} dB");
    // Measured +2.3 / +2.5 dB (20.0 / 19.9 against 22.4 dB, two builds): one colour's error is
    // the environment's spread over the views' directions, which only the spheres can take up.
    assert!(
        p_spheres > p_colour + 1.5,
        "spheres {p_spheres:.2} dB against one colour {p_colour:.2} dB"
    );
    let m = metrics(&spheres);
    assert_eq!(m["background"]["mode"], "spheres");
    assert_eq!(m["background"]["spheres"]["layers"], 16);
    // The checkpoint holds the spheres: resumed into a fresh backend they come back as trained.
    let ck = spheres.join("plenoxels.npz");
    let saved = alphasurf::checkpoint::format::load(&ck).unwrap();
    let (b, ..) = alphasurf::checkpoint::resume::<
        alphasurf::plenoxel::PlenoxelsStage,
        alphasurf::train::PlenoxelsConfig,
        _,
    >(cpu_plenoxels, &ck)
    .unwrap();
    use alphasurf::stage::StageBackend;
    let s = b.spheres().unwrap().expect("spheres restored");
    let table = &saved
        .optim
        .iter()
        .find(|(n, _)| n == "background_spheres")
        .unwrap()
        .1;
    assert!(s.learned() && &s.table == table && s.avg.iter().any(|&a| a > 0.0));
    // Stage 2 composites on them (kept, not learned): its test PSNR is the one `render` gives.
    let s2 = dir.path().join("s2");
    run_ok(
        bin()
            .args(["train", "--stage", "surface", "--init"])
            .arg(&spheres)
            .arg("--data")
            .arg(&data)
            .arg("--out")
            .arg(&s2)
            .args(["--backend", "cpu", "--background", "spheres", "--quiet"])
            .args(["--surface-iters", "100", "--batch", "2048"]),
    );
    let s2_psnr = psnr(&s2);
    assert_eq!(
        metrics(&s2)["background"]["spheres"],
        m["background"]["spheres"]
    );
    let rendered = render_mean_psnr(
        bin()
            .args(["render", "--run"])
            .arg(&s2)
            .arg("--out")
            .arg(dir.path().join("renders"))
            .args(["--backend", "cpu"]),
    );
    eprintln!("stage 2: test PSNR {s2_psnr:.3} dB, rendered {rendered:.3} dB");
    assert!((rendered - s2_psnr).abs() < 0.01, "{rendered} vs {s2_psnr}");
    // A white stage 2 on a spheres run is refused, naming the mode to pass.
    let out = bin()
        .args(["train", "--stage", "surface", "--init"])
        .arg(&spheres)
        .arg("--data")
        .arg(&data)
        .arg("--out")
        .arg(dir.path().join("white"))
        .args(["--backend", "cpu", "--background", "white", "--quiet"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("--background spheres"),
        "{err}"
    );
}

/// A CPU stage-1 backend on `grid` (what `checkpoint::resume` builds in the tests).
fn cpu_plenoxels(
    grid: alphasurf::grid::Grid,
) -> anyhow::Result<Box<alphasurf::plenoxel::CpuPlenoxels>> {
    Ok(Box::new(alphasurf::plenoxel::CpuPlenoxels::new(grid)))
}
