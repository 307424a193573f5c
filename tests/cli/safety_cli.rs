//! Issue 24, "nothing a user owns is ever lost": the hostile user's reproducers as regression
//! tests against the release binary. Outputs never replace inputs, datasets or other runs; writes
//! are atomic (a full disk is a file-size limit of 0 in a child process, with SIGXFSZ ignored so
//! writes fail with EFBIG as on ENOSPC); a resumed log holds each step once; `--stage all`
//! resumes across the stage boundary; a run is locked against a second writer; bad inputs and
//! oversized flags are clear errors (exit code 1, never a panic or an abort).

use alphasurf::checkpoint::format::{self as checkpoint, optim_refs};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

pub(super) fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_alphasurf"))
}

/// The binary under a file-size limit of 0 blocks: every write to a file fails (EFBIG).
pub(super) fn bin_on_full_disk() -> Command {
    bin_with_limit("-f 0")
}

/// The binary under `ulimit LIMIT` (e.g. `-f 1`: a write past one 512-byte block fails with
/// EFBIG, as on a disk that fills up part way; `-v KIB`: an address-space limit).
pub(super) fn bin_with_limit(limit: &str) -> Command {
    let mut c = Command::new("bash");
    c.args([
        "-c",
        &format!("trap '' XFSZ; ulimit {limit}; exec \"$0\" \"$@\""),
    ])
    .arg(env!("CARGO_BIN_EXE_alphasurf"));
    c
}

/// Exit code, stdout, stderr.
pub(super) fn run(cmd: &mut Command) -> (Option<i32>, String, String) {
    let out = cmd.output().expect("spawn alphasurf");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

pub(super) fn run_ok(cmd: &mut Command) -> String {
    let (code, out, err) = run(cmd);
    assert_eq!(code, Some(0), "{cmd:?} failed:\n{out}\n{err}");
    out
}

/// The command fails cleanly (exit code 1, not a panic's 101 or a signal) with a message that
/// contains every one of `needles`; returns the message.
pub(super) fn refused(cmd: &mut Command, needles: &[&str]) -> String {
    let (code, out, err) = run(cmd);
    assert_eq!(
        code,
        Some(1),
        "{cmd:?}: expected a clean error:\n{out}\n{err}"
    );
    assert!(!err.contains("panicked"), "{err}");
    for n in needles {
        assert!(err.contains(n), "{cmd:?}: no {n:?} in:\n{err}");
    }
    err
}

/// The built-in solid scene at 32² pixels and 12 views, in `dir/scene`.
fn scene(dir: &Path) -> PathBuf {
    small_scene(dir, "32", "12")
}

/// The built-in solid scene at `res`² pixels and `views` views, in `dir/scene`.
pub(super) fn small_scene(dir: &Path, res: &str, views: &str) -> PathBuf {
    let data = dir.join("scene");
    run_ok(
        bin()
            .args([
                "make-scene",
                "--kind",
                "solid",
                "--res",
                res,
                "--views",
                views,
            ])
            .args(["--spp", "1", "--gt-spacing", "0.05", "--out"])
            .arg(&data),
    );
    data
}

pub(super) fn train_args<'a>(data: &'a Path, out: &'a Path) -> Vec<&'a std::ffi::OsStr> {
    let mut v: Vec<&std::ffi::OsStr> = vec!["train".as_ref(), "--data".as_ref(), data.as_ref()];
    v.extend(["--out".as_ref(), out.as_os_str()]);
    for a in [
        "--backend",
        "cpu",
        "--res",
        "32",
        "--batch",
        "1024",
        "--quiet",
    ] {
        v.push(a.as_ref());
    }
    v
}

/// A small finished stage-1 run.
pub(super) fn stage1(data: &Path, out: &Path, iters: &str) {
    run_ok(
        bin()
            .args(train_args(data, out))
            .args(["--iters", iters, "--checkpoint-every", "5"]),
    );
}

pub(super) fn read(p: &Path) -> Vec<u8> {
    std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

#[test]
fn outputs_never_replace_inputs_datasets_or_other_runs() {
    let dir = tempfile::tempdir().unwrap();
    let data = scene(dir.path());
    let gt_png = data.join("test/r_0.png");
    let gt = read(&gt_png);
    let r = dir.path().join("run");
    stage1(&data, &r, "20");
    let ckpt = r.join("plenoxels.npz");
    let ck = read(&ckpt);

    // 1. Into the dataset: training and rendering are refused; its images stay ground truth.
    refused(bin().args(train_args(&data, &data)), &["dataset"]);
    refused(
        bin().args(train_args(&data, &data.join("test"))),
        &["dataset"],
    );
    refused(
        bin()
            .args(["render", "--backend", "cpu", "--run"])
            .arg(&r)
            .arg("--out")
            .arg(data.join("test")),
        &["dataset"],
    );
    assert_eq!(read(&gt_png), gt);

    // 2. An existing run without --resume; a non-run folder, even with --overwrite; stage 2 into
    // its own stage-1 run.
    refused(
        bin().args(train_args(&data, &r)),
        &["--resume", "--overwrite"],
    );
    let mine = dir.path().join("mine");
    std::fs::create_dir_all(mine.join("test")).unwrap();
    for f in ["metrics.json", "train_log.csv", "test/r_0.png"] {
        std::fs::write(mine.join(f), "the user's").unwrap();
    }
    refused(bin().args(train_args(&data, &mine)), &["not a run"]);
    refused(
        bin().args(train_args(&data, &mine)).arg("--overwrite"),
        &["not a run"],
    );
    for f in ["metrics.json", "train_log.csv", "test/r_0.png"] {
        assert_eq!(read(&mine.join(f)), b"the user's");
    }
    for extra in [&[][..], &["--overwrite"][..]] {
        refused(
            bin()
                .args(["train", "--stage", "surface", "--backend", "cpu", "--data"])
                .arg(&data)
                .arg("--init")
                .arg(&r)
                .arg("--out")
                .arg(&r)
                .args(extra),
            &["input"],
        );
    }
    // 3. Outputs over the run's checkpoint.
    for cmd in ["extract", "export"] {
        refused(
            bin().args([cmd, "--run"]).arg(&r).arg("--out").arg(&ckpt),
            &["plenoxels.npz"],
        );
    }
    assert_eq!(read(&ckpt), ck);

    // A retrain with --overwrite that fails on its inputs leaves the old run whole...
    refused(
        bin()
            .args(train_args(&data, &r))
            .args(["--overwrite", "--checkpoint-every", "0"]),
        &["--checkpoint-every"],
    );
    assert_eq!(read(&ckpt), ck);
    assert!(r.join("metrics.json").exists() && r.join("run.json").exists());
    // ...and one that runs replaces it, keeping files the run does not own.
    std::fs::write(r.join("notes.txt"), "keep").unwrap();
    run_ok(
        bin()
            .args(train_args(&data, &r))
            .args(["--overwrite", "--iters", "10"]),
    );
    let m: serde_json::Value = serde_json::from_slice(&read(&r.join("metrics.json"))).unwrap();
    assert_eq!(m["config"]["iters"], 10);
    assert_eq!(read(&r.join("notes.txt")), b"keep");
    assert!(!r.join("run.lock").exists(), "the lock is released");
}

#[test]
fn a_full_disk_leaves_previous_outputs_whole() {
    let dir = tempfile::tempdir().unwrap();
    let data = scene(dir.path());
    let r = dir.path().join("run");
    stage1(&data, &r, "60");
    let ply = dir.path().join("cloud.ply");
    let extract = |c: &mut Command| {
        c.args(["extract", "--backend", "cpu", "--levels", "5", "--run"])
            .arg(&r)
            .arg("--out")
            .arg(&ply);
    };
    let mut c = bin();
    extract(&mut c);
    run_ok(&mut c);
    let before = read(&ply);
    assert!(before.len() > 100);
    let mut c = bin_on_full_disk();
    extract(&mut c);
    refused(&mut c, &["cloud.ply"]);
    assert_eq!(read(&ply), before, "the previous PLY is intact");
    assert!(!dir.path().join("cloud.ply.tmp").exists());
    // With room again, the same command replaces its earlier cloud (a rerun is no error).
    let mut c = bin();
    extract(&mut c);
    run_ok(&mut c);
    assert_eq!(read(&ply).len(), before.len());

    // render: an error, no 0-byte PNG, and earlier renders intact.
    let renders = dir.path().join("renders");
    let render = |c: &mut Command| {
        c.args(["render", "--backend", "cpu", "--run"])
            .arg(&r)
            .arg("--out")
            .arg(&renders);
    };
    let mut c = bin_on_full_disk();
    render(&mut c);
    refused(&mut c, &["r_0.png"]);
    assert_eq!(std::fs::read_dir(&renders).unwrap().count(), 0);
    let mut c = bin();
    render(&mut c);
    run_ok(&mut c);
    let png = read(&renders.join("r_0.png"));
    let mut c = bin_on_full_disk();
    render(&mut c);
    refused(&mut c, &["r_0.png"]);
    assert_eq!(read(&renders.join("r_0.png")), png);
    assert!(std::fs::read_dir(&renders)
        .unwrap()
        .all(|e| e.unwrap().metadata().unwrap().len() > 0));
}

/// A periodic checkpoint that fails (a file-size limit stands in for a full disk) stops the run
/// with the reason, instead of training on without one until the next checkpoint or the end.
#[test]
fn a_checkpoint_that_cannot_be_written_stops_training() {
    let dir = tempfile::tempdir().unwrap();
    let data = scene(dir.path());
    let r = dir.path().join("run");
    // 64 KiB per file: the run's records and its log fit, a checkpoint of the 32³ grid does not.
    let mut c = bin_with_limit("-f 128");
    c.args(train_args(&data, &r))
        .args(["--iters", "100000", "--checkpoint-every", "5"]);
    let start = Instant::now();
    let err = refused(&mut c, &["training stopped after step", "plenoxels.npz"]);
    assert!(start.elapsed() < Duration::from_secs(120), "{err}");
    let steps = log_steps(&r.join("train_log.csv"));
    assert!(
        !steps.is_empty() && *steps.last().unwrap() < 100_000,
        "{steps:?}"
    );
}

/// The step column of a training log; every row has the header's field count.
fn log_steps(path: &Path) -> Vec<u32> {
    let text = String::from_utf8(read(path)).unwrap();
    let mut lines = text.lines();
    let fields = lines.next().unwrap().split(',').count();
    lines
        .map(|l| {
            assert_eq!(l.split(',').count(), fields, "malformed row {l:?}");
            l.split(',').next().unwrap().parse().unwrap()
        })
        .collect()
}

#[test]
fn resume_cuts_the_log_back_and_validates_the_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let data = scene(dir.path());
    let r = dir.path().join("run");
    stage1(&data, &r, "20");
    let ckpt = r.join("plenoxels.npz");
    let ck = checkpoint::load(&ckpt).unwrap();
    // What kill -9 leaves: a checkpoint at step 10, log rows past it and a torn last row.
    let mut meta = ck.meta.clone();
    meta["step"] = 10.into();
    checkpoint::save(&ckpt, &ck.grid, &optim_refs(&ck.optim), &meta).unwrap();
    let log = r.join("train_log.csv");
    let mut text = String::from_utf8(read(&log)).unwrap();
    text.push_str("21,1e-2,20.0,1.0\n22,1e-");
    std::fs::write(&log, text).unwrap();
    let out = run_ok(
        bin()
            .args([
                "train",
                "--backend",
                "cpu",
                "--resume",
                "--quiet",
                "--iters",
                "25",
            ])
            .arg("--data")
            .arg(&data)
            .arg("--out")
            .arg(&r),
    );
    assert!(out.contains("stage 1 done"), "{out}");
    assert_eq!(log_steps(&log), (1..=25).collect::<Vec<_>>());

    // A resume flag the checkpoint's configuration cannot honour is an error, not ignored.
    refused(
        bin()
            .args([
                "train",
                "--backend",
                "cpu",
                "--resume",
                "--res",
                "64",
                "--iters",
                "30",
            ])
            .arg("--data")
            .arg(&data)
            .arg("--out")
            .arg(&r),
        &["--res"],
    );
    // An explicit `--preset fast` on a `paper` checkpoint is a clash too, although `fast` is the
    // default (the checkpoint's preset is relabelled here: a real paper run is 50k steps).
    let ck = checkpoint::load(&ckpt).unwrap();
    let mut meta = ck.meta.clone();
    meta["config"]["preset"] = "paper".into();
    checkpoint::save(&ckpt, &ck.grid, &optim_refs(&ck.optim), &meta).unwrap();
    refused(
        bin()
            .args(train_args(&data, &r))
            .args(["--resume", "--preset", "fast", "--iters", "30"]),
        &["--preset", "preset paper"],
    );
    // A checkpoint whose configuration says checkpoint_every 0 is refused (was a panic).
    let ck = checkpoint::load(&ckpt).unwrap();
    let mut meta = ck.meta.clone();
    meta["config"]["checkpoint_every"] = 0.into();
    checkpoint::save(&ckpt, &ck.grid, &optim_refs(&ck.optim), &meta).unwrap();
    refused(
        bin()
            .args(train_args(&data, &r))
            .args(["--resume", "--iters", "30"]),
        &["checkpoint_every"],
    );
}

#[test]
fn stage_all_resumes_across_the_boundary_and_locks_its_run() {
    let dir = tempfile::tempdir().unwrap();
    let data = scene(dir.path());
    let out = dir.path().join("all");
    let all = |c: &mut Command| {
        c.args(train_args(&data, &out)).args(["--stage", "all"]);
    };
    let mut c = bin();
    all(&mut c);
    let mut child = c
        .args(["--iters", "100000", "--checkpoint-every", "5"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let s1_ckpt = out.join("plenoxels/plenoxels.npz");
    let start = Instant::now();
    while !s1_ckpt.exists() {
        assert!(start.elapsed() < Duration::from_secs(120), "no checkpoint");
        std::thread::sleep(Duration::from_millis(50));
    }
    // 11. A second writer is kept out by the lock.
    let mut c = bin();
    all(&mut c);
    refused(c.arg("--resume"), &["in use by process"]);
    child.kill().unwrap();
    child.wait().unwrap();

    // 8. Killed in stage 1: resume finishes stage 1, then runs stage 2.
    let step = checkpoint::load(&s1_ckpt).unwrap().meta["step"]
        .as_u64()
        .unwrap();
    // Stage 2 needs a stage 1 of about 100 steps to find surfaces at this size.
    let s1_iters = (step + 10).max(100);
    let iters = s1_iters.to_string();
    let mut c = bin();
    all(&mut c);
    let text = run_ok(c.args(["--resume", "--iters", &iters, "--surface-iters", "10"]));
    assert!(text.contains("stage 2 done"), "{text}");
    let s1_log = log_steps(&out.join("plenoxels/train_log.csv"));
    assert_eq!(s1_log, (1..=s1_iters as u32).collect::<Vec<_>>());

    // Extending stage 1 under an existing stage 2 is refused; stage 2 alone resumes.
    let more = (s1_iters + 10).to_string();
    let mut c = bin();
    all(&mut c);
    refused(c.args(["--resume", "--iters", &more]), &["stale"]);
    let mut c = bin();
    all(&mut c);
    let text = run_ok(c.args(["--resume", "--surface-iters", "15"]));
    assert!(text.contains("stage 2 done"), "{text}");
    assert_eq!(
        log_steps(&out.join("surface/train_log.csv")),
        (1..=15).collect::<Vec<_>>()
    );
    // 12. render on a `--stage all` run names both stages' runs; export on a stage-2 run names it.
    refused(
        bin()
            .args(["render", "--backend", "cpu", "--run"])
            .arg(&out)
            .arg("--out")
            .arg(dir.path().join("r")),
        &["--stage all", "plenoxels", "surface"],
    );
    refused(
        bin()
            .args(["export", "--run"])
            .arg(out.join("surface"))
            .arg("--out")
            .arg(dir.path().join("c.npz")),
        &["stage-2"],
    );
    refused(
        bin()
            .args(["export", "--run"])
            .arg(&out)
            .arg("--out")
            .arg(dir.path().join("c.npz")),
        &["--stage all"],
    );
    assert!(!out.join("run.lock").exists() && !out.join("surface/run.lock").exists());
}

/// An svox2 checkpoint with a links array of `shape` (every vertex allocated).
pub(super) fn svox2_ckpt(path: &Path, shape: [u64; 3]) {
    let n = shape.iter().product::<u64>();
    let mut w = alphasurf::grid::npz::NpzWriter::new(std::fs::File::create(path).unwrap());
    let links: Vec<i32> = (0..n as i32).collect();
    w.array("links", &shape, &links).unwrap();
    w.array("density_data", &[n, 1], &vec![10f32; n as usize])
        .unwrap();
    w.array("sh_data", &[n, 27], &vec![0.1f32; n as usize * 27])
        .unwrap();
    w.array("radius", &[3], &[1.5f32; 3]).unwrap();
    w.finish().unwrap();
}

#[test]
fn bad_inputs_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let data = small_scene(dir.path(), "16", "5");
    // 6. Grids with an axis of one vertex (a renderer would index past it).
    for shape in [[1, 1, 1], [1, 32, 32], [1, 1, 2]] {
        let ck = dir
            .path()
            .join(format!("{}x{}x{}.npz", shape[0], shape[1], shape[2]));
        svox2_ckpt(&ck, shape);
        refused(
            bin()
                .args(["import", "--ckpt"])
                .arg(&ck)
                .arg("--data")
                .arg(&data)
                .arg("--out")
                .arg(dir.path().join("imported")),
            &["at least 2 vertices"],
        );
    }
    let ok = dir.path().join("2x2x2.npz");
    svox2_ckpt(&ok, [2, 2, 2]);
    run_ok(
        bin()
            .args(["import", "--ckpt"])
            .arg(&ok)
            .arg("--data")
            .arg(&data)
            .arg("--out")
            .arg(dir.path().join("imported")),
    );
    // An svox2 checkpoint has no run, so no training cameras: trimming needs --data.
    refused(
        bin()
            .args([
                "extract",
                "--trim-hidden",
                "on",
                "--backend",
                "cpu",
                "--ckpt",
            ])
            .arg(&ok)
            .arg("--out")
            .arg(dir.path().join("hidden.ply")),
        &["--trim-hidden", "--data"],
    );

    // 7. eval with no distance under --max-dist (a cloud in millimetres).
    let gt = data.join("gt_points.ply");
    let pts = alphasurf::io::read_points(&gt).unwrap();
    let mm = dir.path().join("mm.ply");
    let scaled: Vec<[f32; 3]> = pts.iter().map(|p| p.map(|v| v * 1000.0 + 5000.0)).collect();
    alphasurf::io::write_points(&mm, &scaled).unwrap();
    refused(
        bin().args(["eval", "--pred"]).arg(&mm).arg("--gt").arg(&gt),
        &["no usable distance", "millimetres"],
    );
    run_ok(bin().args(["eval", "--pred"]).arg(&gt).arg("--gt").arg(&gt));

    // 10. camera_angle_x at π in f32 (a negative focal) or in degrees; left-handed cameras warn.
    let transforms = data.join("transforms_train.json");
    let original = String::from_utf8(read(&transforms)).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&original).unwrap();
    // The reproducer's 3.14159265 (below π in f64, past it in f32), as JSON text.
    for angle in ["3.14159265", "7.0", "0.0", "-0.5"] {
        v["camera_angle_x"] = serde_json::from_str(angle).unwrap();
        std::fs::write(&transforms, v.to_string()).unwrap();
        refused(
            bin().arg("inspect").arg(&data),
            &["camera_angle_x", "transforms_train.json"],
        );
    }
    let mut v: serde_json::Value = serde_json::from_str(&original).unwrap();
    for row in v["frames"][0]["transform_matrix"].as_array_mut().unwrap() {
        row[0] = (-row[0].as_f64().unwrap()).into(); // mirror the camera's x axis
    }
    std::fs::write(&transforms, v.to_string()).unwrap();
    let text = run_ok(bin().arg("inspect").arg(&data));
    assert!(text.contains("left-handed"), "{text}");
    // train repeats inspect's warnings (this one then stops at the missing --init).
    let err = refused(
        bin()
            .args(["train", "--stage", "surface", "--backend", "cpu", "--data"])
            .arg(&data)
            .arg("--init")
            .arg(dir.path().join("none"))
            .arg("--out")
            .arg(dir.path().join("s2")),
        &["--init"],
    );
    assert!(
        err.contains("warning") && err.contains("left-handed"),
        "{err}"
    );
    std::fs::write(&transforms, original).unwrap();

    // 12. Flags the stage would ignore; NaN flags.
    let out = dir.path().join("x");
    for (extra, needle) in [
        (&["--category", "translucent"][..], "--category"),
        (&["--set", "lambda_h=1"][..], "--set"),
        (&["--surface-iters", "5"][..], "--surface-iters"),
    ] {
        refused(bin().args(train_args(&data, &out)).args(extra), &[needle]);
    }
    refused(
        bin()
            .args(train_args(&data, &out))
            .args(["--stage", "surface", "--init"])
            .arg(dir.path().join("imported")),
        &["--res"],
    );
    refused(
        bin()
            .args(["extract", "--min-alpha", "NaN", "--run"])
            .arg(dir.path().join("imported"))
            .arg("--out")
            .arg(dir.path().join("p.ply")),
        &["--min-alpha"],
    );
    assert!(!out.exists(), "a refused command creates nothing");
}

#[test]
fn oversized_flags_are_refused_before_allocating() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s");
    for (flag, value) in [
        ("--res", "100000"),
        ("--views", "4000000000"),
        ("--gt-spacing", "1e-6"),
    ] {
        refused(
            bin()
                .args(["make-scene", "--kind", "solid", flag, value, "--out"])
                .arg(&out),
            &[flag],
        );
    }
    assert!(!out.exists());
    let data = small_scene(dir.path(), "16", "5");
    refused(
        bin()
            .args([
                "train",
                "--backend",
                "cpu",
                "--batch",
                "4000000000",
                "--data",
            ])
            .arg(&data)
            .arg("--out")
            .arg(dir.path().join("r")),
        &["--batch 4000000000", "memory"],
    );
}

/// A closed stdout (`alphasurf devices | head` when head has quit) ends the command quietly, as
/// other tools do, instead of a panic on the next print.
#[test]
fn closed_stdout_is_not_a_panic() {
    let mut child = Command::new(env!("CARGO_BIN_EXE_alphasurf"))
        .arg("devices")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_ne!(out.status.code(), Some(101), "{stderr}");
}
