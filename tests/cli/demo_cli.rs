//! `alphasurf demo --fast` end to end at a tiny size (32² images, 12 views, 32³ grid, a few dozen
//! steps): the results table on stdout, report.md, results.json and valid, non-trivial PNG
//! figures. Also `bench time-vs-error` at one tiny point: CSV, PNG and the `--json` line.

use std::collections::HashSet;
use std::path::Path;
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_alphasurf"))
}

/// Hidden size flags shared by the demo and the bench: a scene and run small enough for CI.
const TINY_SCENE: [&str; 10] = [
    "--image-res",
    "32",
    "--views",
    "12",
    "--spp",
    "1",
    "--gt-spacing",
    "0.02",
    "--batch",
    "2048",
];

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

/// A decodable PNG of at least `min` pixels per side with more than `colours` distinct colours.
fn assert_png(path: &Path, min: u32, colours: usize) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert!(
        bytes.starts_with(b"\x89PNG\r\n\x1a\n"),
        "{} is not a PNG",
        path.display()
    );
    let img = image::load_from_memory_with_format(&bytes, image::ImageFormat::Png)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8();
    assert!(
        img.width() >= min && img.height() >= min,
        "{}: {}×{}",
        path.display(),
        img.width(),
        img.height()
    );
    let distinct: HashSet<[u8; 3]> = img.pixels().map(|p| p.0).collect();
    assert!(
        distinct.len() > colours,
        "{}: only {} colours",
        path.display(),
        distinct.len()
    );
    // Not a blank page: a fair share of the pixels is not the background white.
    let ink = img.pixels().filter(|p| p.0 != [255, 255, 255]).count();
    assert!(
        ink * 100 > (img.width() * img.height()) as usize,
        "{}: {ink} non-white pixels",
        path.display()
    );
}

#[test]
fn demo_fast_writes_table_report_and_figures() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    let stdout = run_ok(
        bin()
            .args([
                "demo",
                "--fast",
                "--scene",
                "thin",
                "--backend",
                "cpu",
                "--out",
            ])
            .arg(&out)
            .args(TINY_SCENE)
            .args(["--grid-res", "32", "--iters", "60", "--surface-iters", "30"])
            .args(["--rays-per-axis", "3"]),
    );
    // The table: header, one row per level, the best level.
    let header = stdout
        .lines()
        .find(|l| l.starts_with("method "))
        .unwrap_or_else(|| panic!("no table header in:\n{stdout}"));
    for col in ["Chamfer ×10⁻²", "F1", "test PSNR", "wall time"] {
        assert!(header.contains(col), "header {header:?} lacks {col}");
    }
    for level in ["10", "30", "50", "70", "90", "100"] {
        let row = format!("Plen σ = {level} ");
        assert!(stdout.contains(&row), "no row {row:?} in:\n{stdout}");
    }
    let best = stdout
        .lines()
        .skip_while(|l| !l.starts_with("method "))
        .find(|l| l.starts_with("best Plen (σ = "))
        .unwrap_or_else(|| panic!("no best-level row in:\n{stdout}"));
    assert!(best.contains(" dB"), "{best}");

    let report = std::fs::read_to_string(out.join("report.md")).expect("report.md");
    assert!(report.contains("| method | Chamfer ×10⁻² | F1 | test PSNR | wall time |"));
    let results: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap())
            .expect("results.json");
    let rows = results["rows"].as_array().expect("rows");
    assert!(rows.len() >= 7, "{} rows", rows.len());
    let best = rows
        .iter()
        .find(|r| r["kind"] == "plenoxels_best")
        .expect("best row");
    let chamfer = best["chamfer_e2"].as_f64().expect("best Chamfer");
    assert!(chamfer > 0.0 && chamfer.is_finite());
    assert!(results["stage1"]["test_psnr"].as_f64().unwrap() > 10.0);
    // Every extraction used the requested lattice: the σ = 10 cloud is the one `extract` writes
    // with the same option (and differs from the default lattice's).
    assert_eq!(results["rays_per_axis"], 3);
    assert!(report.contains("--rays-per-axis 3`"), "report command");
    assert!(report.contains(" --grid-res 32 "), "report command");
    assert_eq!(results["grid_res"], 32);
    let sigma10 = out.join("plenoxels/points_sigma10.ply");
    let points = |r: &str| {
        let ply = dir.path().join(format!("r{r}.ply"));
        run_ok(
            bin()
                .args([
                    "extract",
                    "--backend",
                    "cpu",
                    "--levels",
                    "10",
                    "--rays-per-axis",
                    r,
                    "--run",
                ])
                .arg(out.join("plenoxels"))
                .arg("--out")
                .arg(&ply),
        );
        std::fs::read(ply).unwrap()
    };
    assert_eq!(std::fs::read(&sigma10).unwrap(), points("3"));
    assert_ne!(std::fs::read(&sigma10).unwrap(), points("5"));
    check_stage2(&stdout, &report, rows);

    // Renderings and colour-mapped clouds have many colours; line plots have white, black, grid
    // grey and one colour per series.
    for (name, min, colours) in [
        ("test_view.png", 100, 8),
        ("error_cloud.png", 300, 8),
        ("curves.png", 300, 3),
        ("chamfer_levels.png", 300, 3),
        ("meshes.png", 300, 8),
    ] {
        assert!(
            report.contains(&format!("![{name}]({name})")),
            "report lacks {name}"
        );
        assert_png(&out.join(name), min, colours);
    }
    assert!(out.join("plenoxels/train_log.csv").exists());
    assert!(out.join("alphasurf/train_log.csv").exists());
    // The meshes of the best level and of αSurf, both shown in the figure.
    let level = best["level"].as_f64().unwrap();
    for mesh in [
        format!("plenoxels/mesh_sigma{level}.ply"),
        "alphasurf/mesh.ply".into(),
    ] {
        let m = alphasurf::mesh::ply::read_mesh_ply(&out.join(&mesh)).expect(&mesh);
        assert!(!m.faces.is_empty(), "{mesh}");
        assert!(report.contains(&format!("`{mesh}`")), "report lacks {mesh}");
    }
}

#[test]
fn bench_time_vs_error_writes_csv_png_and_json() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("tve");
    let stdout = run_ok(
        bin()
            .args(["bench", "time-vs-error", "--json", "--out"])
            .arg(&out)
            .args(TINY_SCENE)
            .args(["--points", "cpu:32:40,cpu:32:80", "--surface-iters", "30"]),
    );
    let last = stdout.lines().last().expect("output");
    let j: serde_json::Value = serde_json::from_str(last).expect("JSON last line");
    let rows = j["rows"].as_array().expect("rows");
    let plen: Vec<_> = rows
        .iter()
        .filter(|r| r["method"] == "plenoxels_best")
        .collect();
    assert_eq!(plen.len(), 2, "{rows:?}");
    let surf: Vec<_> = rows.iter().filter(|r| r["method"] == "alphasurf").collect();
    assert_eq!(surf.len(), 2, "{rows:?}");
    for r in plen.iter().chain(&surf) {
        assert!(r["wall_s"].as_f64().unwrap() > 0.0);
        assert!(r["train_rays_per_s"].as_f64().unwrap() > 0.0);
        assert!(r["chamfer_e2"].as_f64().unwrap() > 0.0);
        assert!(r["test_psnr"].as_f64().unwrap() > 10.0);
    }
    let csv = std::fs::read_to_string(out.join("time_vs_error.csv")).expect("CSV");
    let lines: Vec<&str> = csv.lines().collect();
    assert!(lines[0].starts_with("scene,backend,res,iters,method,level,wall_s"));
    assert_eq!(lines.len(), 1 + rows.len());
    assert_png(&out.join("time_vs_error.png"), 300, 3);
}

/// Stage 2 ran: an αSurf row in the table and the results, its point cloud evaluated.
fn check_stage2(stdout: &str, report: &str, rows: &[serde_json::Value]) {
    // The table is the last block of the output (subcommands print their own lines before it).
    let line = stdout
        .lines()
        .skip_while(|l| !l.starts_with("method "))
        .find(|l| l.starts_with("αSurf "))
        .unwrap_or_else(|| panic!("no αSurf row in:\n{stdout}"));
    assert!(line.contains(" dB") && line.ends_with(" s"), "{line}");
    assert!(
        stdout.contains("αSurf Chamfer vs best Plenoxels level:"),
        "{stdout}"
    );
    assert!(!report.contains("did not run"));
    let surf = rows
        .iter()
        .find(|r| r["kind"] == "alphasurf")
        .expect("αSurf row in results.json");
    assert!(surf["error"].is_null(), "{surf}");
    assert!(
        surf["chamfer_e2"].as_f64().is_some_and(|c| c > 0.0),
        "{surf}"
    );
    assert!(
        surf["test_psnr"].as_f64().is_some_and(|p| p > 10.0),
        "{surf}"
    );
}
