//! Issue 44, "nothing lost, nothing silently wrong": the findings of a hostile probe as
//! regression tests against the release binary, each in a temporary folder. Replacing a user's
//! folder builds the new one beside it and swaps it in when complete; leftovers of a killed or
//! full-disk run are cleared or named; sizes that allocate are checked against the memory the
//! process may use; a run refuses another dataset than its own; a command whose every unit of
//! work failed exits non-zero; and the unclear errors say what is wrong and what to do.

use super::safety_cli::{
    bin, bin_with_limit, read, refused, run, run_ok, small_scene, stage1, svox2_ckpt, train_args,
};
use std::path::Path;

/// `make-scene` of a small scene into `out`; `extra` flags replace the defaults they name.
fn make_scene(kind: &str, out: &Path, extra: &[&str]) -> (Option<i32>, String, String) {
    let mut c = bin();
    c.args(["make-scene", "--kind", kind, "--out"]).arg(out);
    for (flag, value) in [
        ("--res", "16"),
        ("--views", "5"),
        ("--spp", "1"),
        ("--gt-spacing", "0.05"),
    ] {
        if !extra.contains(&flag) {
            c.args([flag, value]);
        }
    }
    run(c.args(extra))
}

fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// Data lost (3): `make-scene` over a scene, `import --overwrite` over a run, and what a killed or
/// full-disk run leaves.
#[test]
fn replacing_a_folder_loses_nothing_and_leaves_nothing_half_written() {
    let dir = tempfile::tempdir().unwrap();
    let data = small_scene(dir.path(), "16", "5");
    // make-scene into an existing scene: refused without --overwrite, then replaced whole (no
    // views of the old scene beside the new ones), keeping a file of the user's.
    let copy = dir.path().join("scene_copy");
    let (code, _, err) = make_scene("thin", &copy, &[]);
    assert_eq!(code, Some(0), "{err}");
    let (code, _, err) = make_scene("solid", &copy, &["--views", "2"]);
    assert!(code == Some(1) && err.contains("pass --overwrite"), "{err}");
    assert_eq!(names(&copy.join("train")).len(), 5, "left as it was");
    std::fs::write(copy.join("notes.txt"), "mine").unwrap();
    let (code, _, err) = make_scene("solid", &copy, &["--views", "2", "--overwrite"]);
    assert_eq!(code, Some(0), "{err}");
    assert_eq!(names(&copy.join("train")), ["r_0.png", "r_1.png"]);
    assert_eq!(read(&copy.join("notes.txt")), b"mine");
    assert!(!dir.path().join(".scene_copy.partial").exists());
    // A disk that fills part way: the previous scene whole, no half dataset anywhere.
    let before = read(&copy.join("transforms_train.json"));
    let (code, _, err) = run(bin_with_limit("-f 1")
        .args([
            "make-scene",
            "--kind",
            "thin",
            "--res",
            "16",
            "--views",
            "5",
        ])
        .args(["--spp", "1", "--gt-spacing", "0.05", "--overwrite", "--out"])
        .arg(&copy));
    assert_eq!(code, Some(1), "{err}");
    assert_eq!(read(&copy.join("transforms_train.json")), before);
    assert_eq!(names(&copy.join("train")), ["r_0.png", "r_1.png"]);
    assert!(!dir.path().join(".scene_copy.partial").exists(), "{err}");
    // What a killed make-scene leaves (its staging folder, its lock's process gone) is cleared
    // by the next one.
    let killed = dir.path().join("killed");
    let staging = dir.path().join(".killed.partial");
    std::fs::create_dir_all(staging.join("train")).unwrap();
    std::fs::write(staging.join("train/r_0.png"), "half").unwrap();
    std::fs::write(staging.join("run.lock"), "4000000000 no-such-host-here\n").unwrap();
    let (code, _, err) = make_scene("solid", &killed, &[]);
    assert!(code == Some(1) && err.contains("another process"), "{err}");
    std::fs::write(
        staging.join("run.lock"),
        format!("4000000000 {}\n", alphasurf::run::lock::host_name()),
    )
    .unwrap();
    let (code, _, err) = make_scene("solid", &killed, &[]);
    assert_eq!(code, Some(0), "{err}");
    assert!(!staging.exists() && names(&killed.join("train")).len() == 5);

    // import --overwrite over a trained run: the new checkpoint replaces the old one.
    let r = dir.path().join("run");
    stage1(&data, &r, "5");
    let m: serde_json::Value = serde_json::from_slice(&read(&r.join("metrics.json"))).unwrap();
    assert!(
        m["train_rays_per_s"].as_f64().unwrap() > 0.0,
        "a 5-step run has a rate: {m}"
    );
    let old_ck = read(&r.join("plenoxels.npz"));
    let ck = dir.path().join("ck.npz");
    svox2_ckpt(&ck, [4, 4, 4]);
    let import = |c: &mut std::process::Command| {
        c.args(["import", "--overwrite", "--ckpt"])
            .arg(&ck)
            .arg("--data")
            .arg(&data)
            .arg("--out")
            .arg(&r);
    };
    // On a full disk the lock cannot be written: it is removed, not left empty to block the
    // next run.
    let mut c = bin_with_limit("-f 0");
    import(&mut c);
    refused(&mut c, &["run.lock"]);
    assert!(!r.join("run.lock").exists());
    // On a disk that fills part way: the previous run whole, no lock, no raw zip message.
    let mut c = bin_with_limit("-f 1");
    import(&mut c);
    let err = refused(&mut c, &["plenoxels.npz"]);
    assert!(!err.contains("ZipWriter"), "{err}");
    assert_eq!(read(&r.join("plenoxels.npz")), old_ck);
    assert!(!r.join("run.lock").exists() && !dir.path().join(".run.partial").exists());
    // An empty lock left by a process killed while taking it does not block the next run.
    std::fs::write(r.join("run.lock"), "").unwrap();
    let old = std::time::SystemTime::now() - std::time::Duration::from_secs(60);
    std::fs::File::options()
        .write(true)
        .open(r.join("run.lock"))
        .unwrap()
        .set_modified(old)
        .unwrap();
    std::fs::write(r.join("notes.txt"), "mine").unwrap();
    let mut c = bin();
    import(&mut c);
    run_ok(&mut c);
    let loaded = alphasurf::checkpoint::format::load(&r.join("plenoxels.npz")).unwrap();
    assert_eq!(loaded.grid.res, [4, 4, 4]);
    assert_eq!(names(&r), ["notes.txt", "plenoxels.npz", "run.json"]);
    run_ok(
        bin()
            .args(["render", "--backend", "cpu", "--run"])
            .arg(&r)
            .arg("--out")
            .arg(dir.path().join("renders")),
    );

    // A run stopped before its first checkpoint: nothing to resume, and a new run replaces it.
    let stopped = dir.path().join("stopped");
    std::fs::create_dir(&stopped).unwrap();
    std::fs::copy(r.join("run.json"), stopped.join("run.json")).unwrap();
    refused(
        bin().args(train_args(&data, &stopped)).args(["--resume"]),
        &["no checkpoint", "without --resume"],
    );
    run_ok(
        bin()
            .args(train_args(&data, &stopped))
            .args(["--iters", "3"]),
    );
    assert!(stopped.join("plenoxels.npz").exists());
}

/// Aborts (4): every size that allocates is checked first, naming the flag and the figure.
#[test]
fn sizes_that_allocate_are_refused_before_allocating() {
    let dir = tempfile::tempdir().unwrap();
    let data = small_scene(dir.path(), "16", "5");
    let out = dir.path().join("r");
    for (set, needle) in [
        ("res=5000", "8 ..= 1024"),
        ("upsample=[[3,4000]]", "8 ..= 1024"),
    ] {
        refused(
            bin()
                .args(train_args(&data, &out))
                .args(["--plenoxels-set", set]),
            &[&format!("--plenoxels-set {set}"), needle],
        );
    }
    // The process's own address-space limit, not only the machine's memory.
    refused(
        bin_with_limit("-v 8000000")
            .args([
                "train",
                "--backend",
                "cpu",
                "--quiet",
                "--res",
                "1024",
                "--data",
            ])
            .arg(&data)
            .arg("--out")
            .arg(&out),
        &["--res 1024", "ulimit -v"],
    );
    assert!(!out.exists());
    let mesh = dir.path().join("tri.ply");
    std::fs::write(
        &mesh,
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
         property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n\
         0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
    )
    .unwrap();
    refused(
        bin()
            .args(["eval", "--mesh-samples", "4000000000", "--pred"])
            .arg(&mesh)
            .arg("--gt")
            .arg(data.join("gt_points.ply")),
        &["--mesh-samples 4000000000", "memory"],
    );
    refused(
        bin().args(["bench", "cubic", "--cases", "4000000000"]),
        &["--cases 4000000000", "memory"],
    );
}

/// Silently wrong: another dataset under `--resume` / `--init`; flags that would be ignored;
/// benches whose every point failed; a val split that is not there.
#[test]
fn a_run_refuses_another_dataset_and_nothing_passes_silently() {
    let dir = tempfile::tempdir().unwrap();
    let data = small_scene(dir.path(), "16", "5");
    // The same cameras, image names and sizes: only the pixels differ.
    let other = dir.path().join("other");
    let (code, _, err) = make_scene("thin", &other, &[]);
    assert_eq!(code, Some(0), "{err}");
    let r = dir.path().join("run");
    stage1(&data, &r, "5");
    let info = read(&r.join("run.json"));
    refused(
        bin()
            .args(train_args(&other, &r))
            .args(["--resume", "--iters", "8"]),
        &["--resume", "fingerprint", "--allow-other-data"],
    );
    assert_eq!(read(&r.join("run.json")), info, "run.json untouched");
    let s2 = |init: &Path, data: &Path, extra: &[&str]| {
        let mut c = bin();
        c.args(["train", "--stage", "surface", "--backend", "cpu", "--quiet"])
            .args(["--batch", "1024", "--init"])
            .arg(init)
            .arg("--data")
            .arg(data)
            .arg("--out")
            .arg(dir.path().join("s2"))
            .args(extra);
        c
    };
    refused(
        &mut s2(&r, &other, &["--surface-iters", "3"]),
        &["--init", "--allow-other-data"],
    );
    assert!(!dir.path().join("s2").exists());
    // Both step counts for stage 2: one would be ignored.
    refused(
        &mut s2(&r, &data, &["--iters", "50", "--surface-iters", "3"]),
        &["--iters and --surface-iters"],
    );
    // A copy of the dataset elsewhere is the same data; the flag lets another one through.
    let copy = dir.path().join("copy");
    std::fs::create_dir(&copy).unwrap();
    for e in walk(&data) {
        let to = copy.join(e.strip_prefix(&data).unwrap());
        std::fs::create_dir_all(to.parent().unwrap()).unwrap();
        std::fs::copy(&e, &to).unwrap();
    }
    run_ok(
        bin()
            .args(train_args(&copy, &r))
            .args(["--resume", "--iters", "7"]),
    );
    let (code, _, err) = run(bin().args(train_args(&other, &r)).args([
        "--resume",
        "--iters",
        "9",
        "--allow-other-data",
    ]));
    assert!(code == Some(0) && err.contains("warning"), "{err}");
    // A run from before fingerprints were recorded: compared by its folder.
    let mut v: serde_json::Value = serde_json::from_slice(&read(&r.join("run.json"))).unwrap();
    v.as_object_mut().unwrap().remove("identity");
    std::fs::write(r.join("run.json"), v.to_string()).unwrap();
    refused(
        bin()
            .args(train_args(&data, &r))
            .args(["--resume", "--iters", "10"]),
        &["another folder", "--allow-other-data"],
    );
    refused(
        bin()
            .args(train_args(&data, &dir.path().join("x")))
            .arg("--allow-other-data"),
        &["--allow-other-data applies with --resume"],
    );

    // A bench whose every point failed exits non-zero (its table and CSV are still written).
    let tve = dir.path().join("tve");
    refused(
        bin()
            .args([
                "bench",
                "time-vs-error",
                "--points",
                "cpu:16:10",
                "--no-surface",
            ])
            .args(["--image-res", "32", "--views", "12", "--spp", "1"])
            .args(["--gt-spacing", "0.02", "--out"])
            .arg(&tve),
        &["every sweep point's method failed"],
    );
    assert!(tve.join("time_vs_error.csv").exists());

    // render --split val of a dataset without one.
    std::fs::remove_file(copy.join("transforms_val.json")).unwrap();
    let mut v: serde_json::Value = serde_json::from_slice(&read(&r.join("run.json"))).unwrap();
    v["data"] = copy.to_string_lossy().into_owned().into();
    std::fs::write(r.join("run.json"), v.to_string()).unwrap();
    refused(
        bin()
            .args(["render", "--backend", "cpu", "--split", "val", "--run"])
            .arg(&r)
            .arg("--out")
            .arg(dir.path().join("val")),
        &["no validation split", "--split test"],
    );
}

/// Every file under `dir`.
fn walk(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else {
            out.push(p);
        }
    }
    out
}

/// The unclear errors: each says what is wrong and what to do.
#[test]
fn errors_say_what_is_wrong_and_what_to_do() {
    let dir = tempfile::tempdir().unwrap();
    let data = small_scene(dir.path(), "16", "5");
    refused(
        bin().args(["check-kernels", "--only", "zzznope"]),
        &["matches no kernel", "dda_walk"],
    );
    // extract names both ways of giving a grid.
    let (code, _, err) = run(bin().args(["extract", "--out", "x.ply"]));
    assert!(code == Some(2) && err.contains("--ckpt"), "{err}");
    // A `--stage all` run given where one of its stage runs is meant.
    let all = dir.path().join("all");
    run_ok(bin().args(train_args(&data, &all)).args([
        "--stage",
        "all",
        "--iters",
        "20",
        "--surface-iters",
        "3",
    ]));
    refused(
        bin()
            .args(["extract", "--backend", "cpu", "--run"])
            .arg(&all)
            .arg("--out")
            .arg(dir.path().join("p.ply")),
        &["--stage all", "all/surface"],
    );
    refused(
        bin()
            .args(["train", "--stage", "surface", "--backend", "cpu", "--init"])
            .arg(&all)
            .arg("--data")
            .arg(&data)
            .arg("--out")
            .arg(dir.path().join("s2")),
        &["--stage all", "all/plenoxels"],
    );
    // Stage 2 from a stage 1 that stopped before its last step says so.
    let s1 = all.join("plenoxels");
    let ck = alphasurf::checkpoint::format::load(&s1.join("plenoxels.npz")).unwrap();
    let mut meta = ck.meta.clone();
    meta["step"] = 10.into();
    let optim = alphasurf::checkpoint::format::optim_refs(&ck.optim);
    alphasurf::checkpoint::format::save(&s1.join("plenoxels.npz"), &ck.grid, &optim, &meta)
        .unwrap();
    let (code, _, err) = run(bin()
        .args(["train", "--stage", "surface", "--backend", "cpu", "--quiet"])
        .args(["--batch", "1024", "--surface-iters", "3", "--init"])
        .arg(&s1)
        .arg("--data")
        .arg(&data)
        .arg("--out")
        .arg(dir.path().join("from_stopped")));
    assert!(
        code == Some(0) && err.contains("stopped at step 10 of 20"),
        "{err}"
    );
    // Values a flag cannot mean.
    for (flag, value, needle) in [
        ("--levels", "-5", "must be positive"),
        ("--scene-scale", "1e30", "--scene-scale"),
    ] {
        refused(
            bin()
                .args(["extract", "--backend", "cpu", flag, value, "--run"])
                .arg(all.join("plenoxels"))
                .arg("--out")
                .arg(dir.path().join("p.ply")),
            &[needle],
        );
    }
    let (code, _, err) = make_scene("solid", &dir.path().join("spp"), &["--spp", "100000"]);
    assert!(code == Some(1) && err.contains("--spp 100000"), "{err}");
    // An empty grid: said so, not a range of ±f32::MAX.
    let empty = dir.path().join("empty.npz");
    let mut w = alphasurf::grid::npz::NpzWriter::new(std::fs::File::create(&empty).unwrap());
    w.array("links", &[4, 4, 4], &[-1i32; 64]).unwrap();
    w.array("density_data", &[0, 1], &[0f32; 0]).unwrap();
    w.array("sh_data", &[0, 27], &[0f32; 0]).unwrap();
    w.array("radius", &[3], &[1f32; 3]).unwrap();
    w.finish().unwrap();
    let err = refused(
        bin()
            .args(["extract", "--backend", "cpu", "--ckpt"])
            .arg(&empty)
            .arg("--out")
            .arg(dir.path().join("e.ply")),
        &["holds no vertex"],
    );
    assert!(!err.contains("e38"), "{err}");
    // A symbolic link loop where an image should be: the reason, not "not found".
    let img = data.join("train/r_0.png");
    let png = read(&img);
    std::fs::remove_file(&img).unwrap();
    std::os::unix::fs::symlink("r_0.png", &img).unwrap();
    refused(
        bin().arg("inspect").arg(&data),
        &["r_0.png", "cannot read image"],
    );
    std::fs::remove_file(&img).unwrap();
    std::fs::write(&img, png).unwrap();
    // A principal point far outside the image is a warning of inspect (and so of train).
    let t = data.join("transforms_test.json");
    let mut v: serde_json::Value = serde_json::from_slice(&read(&t)).unwrap();
    let fl = 8.0 / (v["camera_angle_x"].as_f64().unwrap() / 2.0).tan();
    v["fl_x"] = fl.into();
    v["fl_y"] = fl.into();
    v["cx"] = 1e6.into();
    v["cy"] = 8.0.into();
    std::fs::write(&t, v.to_string()).unwrap();
    let (_, out, err) = run(bin().arg("inspect").arg(&data));
    assert!(
        format!("{out}{err}").contains("principal point outside the image"),
        "{out}{err}"
    );
}
