//! Extraction and evaluation: Chamfer/F-score against brute force, PLY errors, thinning
//! invariants, extraction on analytic fields (CPU twin and Vulkan), and extract → eval end to end.

use alphasurf::abi::extract::ExtractInput;
use alphasurf::cpu::extract_points::extract_points;
use alphasurf::eval::extract::{
    allocated_cells, extract_sorted, to_cloud, ExtractBackend, GridFrame,
};
use alphasurf::eval::metrics::from_distances;
use alphasurf::eval::{evaluate, thin, thin_levels, EvalOptions};
use alphasurf::grid::{npz, Grid};
use alphasurf::io::{read_ply, write_points, ExtraValues};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use std::path::{Path, PathBuf};
use std::process::Command;

fn random_cloud(rng: &mut Pcg64, n: usize, spread: f32) -> Vec<[f32; 3]> {
    (0..n)
        .map(|_| [0; 3].map(|_| rng.random_range(-spread..spread)))
        .collect()
}

fn dist(a: &[f32; 3], b: &[f32; 3]) -> f64 {
    (0..3)
        .map(|k| (a[k] as f64 - b[k] as f64).powi(2))
        .sum::<f64>()
        .sqrt()
}

fn brute_nn(from: &[[f32; 3]], to: &[[f32; 3]]) -> Vec<f64> {
    from.iter()
        .map(|p| to.iter().map(|q| dist(p, q)).fold(f64::INFINITY, f64::min))
        .collect()
}

fn rel_eq(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12 * b.abs().max(1e-300)
}

#[test]
fn metrics_match_brute_force() {
    let mut rng = Pcg64::seed_from_u64(7);
    for (np, ng, spread) in [(1, 1, 0.1), (200, 350, 1.0), (500, 80, 3.0)] {
        let pred = random_cloud(&mut rng, np, spread);
        // GT: part near the prediction, part far away (beyond max_dist for some points).
        let mut gt = random_cloud(&mut rng, ng, spread);
        for (i, p) in pred.iter().take(ng / 3).enumerate() {
            gt[i] = p.map(|x| x + rng.random_range(-0.01f32..0.01));
        }
        let opts = EvalOptions {
            max_dist: 0.4,
            threshold: 0.05,
        };
        let m = evaluate(&pred, &gt, &opts).unwrap();
        let (d2s, s2d) = (brute_nn(&pred, &gt), brute_nn(&gt, &pred));
        let b = from_distances(&d2s, &s2d, &opts);
        // Brute force once more by hand, independent of from_distances.
        let mean = |d: &[f64]| {
            let v: Vec<f64> = d.iter().copied().filter(|&x| x < opts.max_dist).collect();
            v.iter().sum::<f64>() / v.len() as f64
        };
        let frac =
            |d: &[f64]| d.iter().filter(|&&x| x < opts.threshold).count() as f64 / d.len() as f64;
        let (p, r) = (frac(&d2s), frac(&s2d));
        assert!(
            rel_eq(m.mean_d2s, mean(&d2s)),
            "{} vs {}",
            m.mean_d2s,
            mean(&d2s)
        );
        assert!(
            rel_eq(m.mean_s2d, mean(&s2d)),
            "{} vs {}",
            m.mean_s2d,
            mean(&s2d)
        );
        assert!(rel_eq(m.chamfer, 0.5 * (mean(&d2s) + mean(&s2d))));
        assert!(rel_eq(m.chamfer, b.chamfer));
        assert_eq!((m.precision, m.recall), (p, r));
        let f1 = if p + r > 0.0 {
            2.0 * p * r / (p + r)
        } else {
            0.0
        };
        assert!(rel_eq(m.f1, f1) || (m.f1 == 0.0 && f1 == 0.0));
        assert_eq!((m.n_pred, m.n_gt), (np, ng));
        assert_eq!(m.d2s_used, d2s.iter().filter(|&&x| x < 0.4).count());
    }
    // Identical clouds: zero distances, perfect scores.
    let pts = random_cloud(&mut rng, 100, 1.0);
    let m = evaluate(&pts, &pts, &EvalOptions::default()).unwrap();
    assert_eq!(
        (m.chamfer, m.precision, m.recall, m.f1),
        (0.0, 1.0, 1.0, 1.0)
    );
    assert!(evaluate(&[], &pts, &EvalOptions::default()).is_err());
}

/// No two kept points within `r`; every dropped point within `cover` of a kept one.
fn check_thinned_cover(points: &[[f32; 3]], kept: &[usize], r: f64, cover: f64) {
    for (a, &i) in kept.iter().enumerate() {
        for &j in &kept[a + 1..] {
            assert!(
                dist(&points[i], &points[j]) > r,
                "kept {i} and {j} within {r}"
            );
        }
    }
    let mut is_kept = vec![false; points.len()];
    for &i in kept {
        is_kept[i] = true;
    }
    for (i, p) in points.iter().enumerate() {
        if !is_kept[i] {
            assert!(
                kept.iter().any(|&k| dist(p, &points[k]) <= cover),
                "dropped point {i} has no kept point within {cover}"
            );
        }
    }
}

fn check_thinned(points: &[[f32; 3]], kept: &[usize], r: f64) {
    check_thinned_cover(points, kept, r, r);
}

#[test]
fn thinning_invariants() {
    let mut rng = Pcg64::seed_from_u64(3);
    let r = 0.05;
    // Clusters of near-duplicates plus scattered points.
    let mut pts = random_cloud(&mut rng, 300, 0.5);
    for i in 0..300 {
        let c = pts[i];
        for _ in 0..3 {
            pts.push(c.map(|x| x + rng.random_range(-0.03f32..0.03)));
        }
    }
    let kept = thin(&pts, r).unwrap();
    assert!(kept.len() < pts.len() && kept.len() > 50);
    assert!(kept.windows(2).all(|w| w[0] < w[1]));
    check_thinned(&pts, &kept, r);
    assert_eq!(thin(&pts, 0.0).unwrap().len(), pts.len());
    assert!(thin(&[], r).unwrap().is_empty());
    // Per level, then on the union.
    let levels: Vec<u32> = (0..pts.len()).map(|i| (i % 3) as u32).collect();
    // Two stages: a point dropped per level is within r of a per-level survivor, which the union
    // stage may drop in turn for another within r, so the cover radius is 2r.
    let kept = thin_levels(&pts, &levels, 3, r).unwrap();
    check_thinned_cover(&pts, &kept, r, 2.0 * r);
    for l in 0..3u32 {
        let idx: Vec<usize> = (0..pts.len()).filter(|&i| levels[i] == l).collect();
        let sub: Vec<[f32; 3]> = idx.iter().map(|&i| pts[i]).collect();
        check_thinned(&sub, &thin(&sub, r).unwrap(), r);
    }
    assert!(thin_levels(&pts, &levels, 2, r).is_err());
}

/// A 20³ grid (all vertices allocated except one corner region) whose density is `f(vertex)`.
fn analytic_grid(f: impl Fn([f32; 3]) -> f32) -> Grid {
    let res = 20u32;
    let mut g = Grid {
        res: [res; 3],
        center: [0.1, -0.05, 0.0],
        radius: [1.0; 3],
        links: Vec::new(),
        density: Vec::new(),
        sh: Vec::new(),
    };
    let mut links = vec![-1; g.slots()];
    for (s, l) in links.iter_mut().enumerate() {
        let v = g.vertex(s);
        if v.iter().all(|&x| x < 4) {
            continue; // an unallocated block: its cells must produce nothing
        }
        *l = g.density.len() as i32;
        g.density.push(f(v.map(|x| x as f32)));
        g.sh.extend_from_slice(&[0.0; 27]);
    }
    g.links = links;
    g
}

fn frame(g: &Grid) -> GridFrame {
    GridFrame {
        res: g.res,
        center: g.center,
        radius: g.radius,
        scene_scale: 2.0 / 3.0,
        ndc: None,
    }
}

/// Blender point → grid coordinates (f64).
fn to_grid(g: &Grid, p: &[f32; 3]) -> [f64; 3] {
    std::array::from_fn(|i| {
        let w = p[i] as f64 * (2.0 / 3.0);
        ((w - g.center[i] as f64) / (2.0 * g.radius[i] as f64) + 0.5) * g.res[i] as f64 - 0.5
    })
}

fn extract_both(g: &Grid, levels: &[f32]) -> Vec<alphasurf::io::PointCloud> {
    let cells = allocated_cells(g.res, &g.links).unwrap();
    let inp = ExtractInput {
        cells: &cells,
        links: &g.links,
        field: &g.density,
        opacity: None,
        levels,
        res: g.res,
        rays_per_axis: 5,
        min_opacity: 0.1,
    };
    let gpu = alphasurf::gpu::test_gpu();
    let mut clouds = Vec::new();
    for backend in [ExtractBackend::Cpu, ExtractBackend::Vulkan(gpu)] {
        // A tiny initial capacity exercises the retry on the device.
        let (pts, stats) = extract_sorted(backend, &inp, Some(16)).unwrap();
        assert!(pts.iter().all(|p| p.level < levels.len() as u32));
        assert!(pts
            .iter()
            .all(|p| p.local.iter().all(|&x| (0.0..=1.0).contains(&x))));
        assert!(pts.iter().all(|p| p.alpha == 1.0));
        if let ExtractBackend::Vulkan(_) = backend {
            assert_eq!(stats.retries, 1);
        }
        let (cloud, _) = to_cloud(&pts, levels, &frame(g), 0.001).unwrap();
        clouds.push(cloud);
    }
    assert!(gpu.validation_messages().is_empty());
    clouds
}

fn extra<'a>(c: &'a alphasurf::io::PointCloud, name: &str) -> &'a [f32] {
    match &c.extras.iter().find(|e| e.name == name).unwrap().values {
        ExtraValues::Float(v) => v,
        _ => panic!("{name} not float"),
    }
}

#[test]
fn extraction_on_a_linear_field_lies_on_the_plane() {
    // σ = a·x + b·y + c·z + d is reproduced exactly by trilinear interpolation.
    let (a, b, c, d) = (2.0f32, -1.0f32, 0.5f32, 20.0f32);
    let g = analytic_grid(|v| a * v[0] + b * v[1] + c * v[2] + d);
    let levels = [25.0f32, 40.0];
    let norm = ((a * a + b * b + c * c) as f64).sqrt();
    for cloud in extract_both(&g, &levels) {
        assert!(cloud.points.len() > 1000, "{}", cloud.points.len());
        let (lv, nx, ny, nz) = (
            extra(&cloud, "level"),
            extra(&cloud, "nx"),
            extra(&cloud, "ny"),
            extra(&cloud, "nz"),
        );
        for (i, p) in cloud.points.iter().enumerate() {
            let q = to_grid(&g, p);
            let f = a as f64 * q[0] + b as f64 * q[1] + c as f64 * q[2] + d as f64;
            let off = (f - lv[i] as f64).abs() / norm;
            assert!(
                off < 1e-3,
                "point {i} {q:?} is {off} voxel off level {}",
                lv[i]
            );
            // Normal: toward increasing σ.
            let n = [nx[i], ny[i], nz[i]];
            let dot = (n[0] * a + n[1] * b + n[2] * c) as f64 / norm;
            assert!((dot - 1.0).abs() < 1e-5, "normal {n:?}");
        }
        for &l in &levels {
            assert!(lv.contains(&l));
        }
        assert!(extra(&cloud, "alpha").iter().all(|&x| x == 1.0));
    }
}

#[test]
fn extraction_on_a_spherical_field_lies_on_the_trilinear_level_set() {
    let c = [10.3f32, 9.7, 10.1];
    let g = analytic_grid(|v| {
        100.0
            - 10.0 * ((v[0] - c[0]).powi(2) + (v[1] - c[1]).powi(2) + (v[2] - c[2]).powi(2)).sqrt()
    });
    let levels = [30.0f32, 50.0];
    let clouds = extract_both(&g, &levels);
    for cloud in &clouds {
        let lv = extra(cloud, "level");
        for (i, p) in cloud.points.iter().enumerate() {
            // Trilerp in f64 at the point; distance to the level set ≈ |f − τ| / |∇f|.
            let q = to_grid(&g, p);
            let base = q.map(|x| (x.floor() as i64).clamp(0, 18) as u32);
            let t: [f64; 3] = std::array::from_fn(|k| q[k] - base[k] as f64);
            let (mut f, mut gr) = (0.0, [0.0f64; 3]);
            for k in 0..8u32 {
                let bit = [k >> 2, (k >> 1) & 1, k & 1];
                let v = g.density
                    [g.links[g.slot(base[0] + bit[0], base[1] + bit[1], base[2] + bit[2])] as usize]
                    as f64;
                let w: [f64; 3] =
                    std::array::from_fn(|m| if bit[m] == 1 { t[m] } else { 1.0 - t[m] });
                f += v * w[0] * w[1] * w[2];
                for m in 0..3 {
                    let dw = if bit[m] == 1 { 1.0 } else { -1.0 };
                    gr[m] += v * dw * w[(m + 1) % 3] * w[(m + 2) % 3];
                }
            }
            let gn = (gr[0] * gr[0] + gr[1] * gr[1] + gr[2] * gr[2]).sqrt();
            let off = (f - lv[i] as f64).abs() / gn;
            assert!(
                off < 1e-3,
                "point {i} at {q:?}: {off} voxel off level {}",
                lv[i]
            );
            // Roughly on the sphere of radius (100 − τ)/10 voxel.
            let rad = (0..3)
                .map(|k| (q[k] - c[k] as f64).powi(2))
                .sum::<f64>()
                .sqrt();
            assert!((rad - (100.0 - lv[i] as f64) / 10.0).abs() < 0.1, "{rad}");
        }
    }
    // Both backends give the same thinned clouds up to rounding.
    assert!(
        clouds[0].points.len().abs_diff(clouds[1].points.len()) <= clouds[0].points.len() / 1000
    );
    let m = evaluate(
        &clouds[0].points,
        &clouds[1].points,
        &EvalOptions::default(),
    )
    .unwrap();
    assert!(m.chamfer < 1e-4, "{m:?}");
}

#[test]
fn cpu_twin_finds_one_point_per_ray_and_level_through_a_plane() {
    // σ = x: each cell crossing the level gets exactly R² points from the x rays.
    let g = analytic_grid(|v| v[0]);
    let cells = allocated_cells(g.res, &g.links).unwrap();
    let levels = [7.5f32];
    let inp = ExtractInput {
        cells: &cells,
        links: &g.links,
        field: &g.density,
        opacity: None,
        levels: &levels,
        res: g.res,
        rays_per_axis: 3,
        min_opacity: 0.0,
    };
    let pts = extract_points(&inp);
    let crossing = cells
        .iter()
        .filter(|&&s| g.vertex(s as usize)[0] == 7)
        .count();
    assert_eq!(pts.len(), 9 * crossing);
    assert!(pts
        .iter()
        .all(|p| (p.local[0] - 0.5).abs() < 1e-6 && p.ray < 9));
}

fn bin() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_alphasurf"));
    c.env(
        "VK_DRIVER_FILES",
        "/usr/share/vulkan/icd.d/lvp_icd.x86_64.json",
    );
    c
}

/// `eval --json --downsample 0` of `pred` against `gt` with `extra` flags.
fn eval_exact<S: AsRef<std::ffi::OsStr>>(
    pred: &Path,
    gt: &Path,
    extra: &[S],
) -> std::process::Output {
    bin()
        .args(["eval", "--json", "--downsample", "0", "--pred"])
        .arg(pred)
        .arg("--gt")
        .arg(gt)
        .args(extra)
        .output()
        .unwrap()
}

fn eval_cmd(pred: &Path, gt: &Path) -> std::process::Output {
    bin()
        .args(["eval", "--json", "--pred"])
        .arg(pred)
        .arg("--gt")
        .arg(gt)
        .output()
        .unwrap()
}

#[test]
fn eval_rejects_unreadable_and_empty_ply() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.ply");
    write_points(&good, &[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]).unwrap();
    let empty = dir.path().join("empty.ply");
    std::fs::write(
        &empty,
        "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
    )
    .unwrap();
    let garbage = dir.path().join("garbage.ply");
    std::fs::write(&garbage, "this is not a ply file").unwrap();
    let missing = dir.path().join("missing.ply");
    for (pred, gt, bad) in [
        (&empty, &good, &empty),
        (&good, &empty, &empty),
        (&garbage, &good, &garbage),
        (&good, &missing, &missing),
    ] {
        let out = eval_cmd(pred, gt);
        assert!(!out.status.success());
        let err = String::from_utf8_lossy(&out.stderr);
        let name = bad.file_name().unwrap().to_str().unwrap();
        assert!(err.contains(name), "stderr does not name {name}: {err}");
    }
    let out = eval_cmd(&good, &good);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn eval_splits_the_chamfer_distance_over_the_scene_objects() {
    let dir = tempfile::tempdir().unwrap();
    // GT: a rod (x axis, 4 points) and a post (z axis, 3 points); scene.json lists them out of
    // order. The prediction sits 0.1 off the rod and 0.3 off the post.
    let cloud = |name: &str, rod_y: f32, post_y: f32| {
        let pts: Vec<[f32; 3]> = (0..4)
            .map(|i| [i as f32, rod_y, 0.0])
            .chain((0..3).map(|i| [10.0, post_y, i as f32]))
            .collect();
        let path = dir.path().join(name);
        write_points(&path, &pts).unwrap();
        path
    };
    let gt = cloud("gt_points.ply", 0.0, 0.0);
    let pred = cloud("pred.ply", 0.1, 0.3);
    let scene = |post: usize| {
        format!(
            r#"{{"objects": [{{"name": "post_0", "point_start": 4, "point_count": {post}}},
                {{"name": "rod", "point_start": 0, "point_count": 4}}]}}"#
        )
    };
    std::fs::write(dir.path().join("scene.json"), scene(3)).unwrap();
    let out = eval_cmd(&pred, &gt);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}");
    let j: serde_json::Value = serde_json::from_str(text.lines().last().unwrap()).unwrap();
    let objects = j["metrics"]["objects"].as_array().unwrap();
    let group = |name: &str| objects.iter().find(|o| o["name"] == name).unwrap().clone();
    let (rod, post) = (group("rod"), group("post"));
    let f = |v: &serde_json::Value| v.as_f64().unwrap();
    assert_eq!(
        (rod["n_gt"].as_u64(), post["n_gt"].as_u64()),
        (Some(4), Some(3))
    );
    assert_eq!(
        (rod["n_pred"].as_u64(), post["n_pred"].as_u64()),
        (Some(4), Some(3))
    );
    for (g, d) in [(&rod, 0.1), (&post, 0.3)] {
        assert!((f(&g["mean_d2s"]) - d).abs() < 1e-6 && (f(&g["mean_s2d"]) - d).abs() < 1e-6);
    }
    let chamfer = f(&j["metrics"]["chamfer"]);
    assert!((f(&rod["chamfer_share"]) + f(&post["chamfer_share"]) - chamfer).abs() < 1e-9);
    assert!((f(&rod["chamfer_share"]) - 0.4 / 7.0).abs() < 1e-6, "{rod}");
    assert!(text.contains("per object group"), "{text}");

    // A scene.json next to the GT that does not match it: reported, the split skipped.
    std::fs::write(dir.path().join("scene.json"), scene(2)).unwrap();
    let out = eval_cmd(&pred, &gt);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}");
    assert!(
        text.contains("no split over objects") && text.contains("scene.json"),
        "{text}"
    );
    assert!(!text.contains("\"objects\""), "{text}");
    // The same file named with --scene is an error naming it.
    let bad = dir.path().join("scene.json");
    let out = bin()
        .args(["eval", "--pred"])
        .arg(&pred)
        .arg("--gt")
        .arg(&gt)
        .arg("--scene")
        .arg(&bad)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("scene.json") && err.contains("cover 6"),
        "{err}"
    );
}

/// Points and meshes carry the surface colour, SH band 0 as 8-bit `red green blue` vertex
/// properties: on a sphere whose band-0 red grows with x (0 at the grid's low face, 255 at its
/// high one), green is 0.5 and blue 0.9, each point and mesh vertex read back has red within 2 of
/// 255·(grid x)/(res − 1) at its position, green 128 and blue 230.
/// Density 100 at voxel (10, 10, 10) falling off by 10 a voxel: σ = 50 on a sphere of radius 5
/// voxels.
fn sphere_grid() -> Grid {
    analytic_grid(|v| {
        100.0
            - 10.0 * ((v[0] - 10.0).powi(2) + (v[1] - 10.0).powi(2) + (v[2] - 10.0).powi(2)).sqrt()
    })
}

/// `extract --levels 50 --backend cpu` of `g` (saved in `dir` as an svox2 checkpoint) into points
/// and a mesh, with the `extra` arguments; the two files' paths (the command must succeed).
fn extract_points_and_mesh(dir: &Path, g: &Grid, extra: &[&str]) -> (PathBuf, PathBuf) {
    let ckpt = dir.join("ckpt.npz");
    npz::save_svox2(g, &ckpt).unwrap();
    let (pts, mesh) = (dir.join("p.ply"), dir.join("m.ply"));
    let out = bin()
        .args(["extract", "--levels", "50", "--backend", "cpu", "--ckpt"])
        .arg(&ckpt)
        .arg("--out")
        .arg(&pts)
        .arg("--mesh")
        .arg(&mesh)
        .args(extra)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    (pts, mesh)
}

#[test]
fn extracted_points_and_meshes_carry_the_surface_colour() {
    use alphasurf::math::sh::SH_C0;
    let dir = tempfile::tempdir().unwrap();
    let mut g = sphere_grid();
    let top = (g.res[0] - 1) as f32;
    for slot in 0..g.slots() {
        let l = g.links[slot];
        if l >= 0 {
            let x = g.vertex(slot)[0] as f32;
            let row = &mut g.sh[27 * l as usize..][..27];
            row[0] = (x / top - 0.5) / SH_C0;
            row[9] = 0.0;
            row[18] = 0.4 / SH_C0;
        }
    }
    let (pts, mesh) = extract_points_and_mesh(dir.path(), &g, &[]);
    let header = std::fs::read(&mesh).unwrap();
    let header = String::from_utf8_lossy(&header[..600]);
    assert!(
        header.contains("property uchar red\nproperty uchar green\nproperty uchar blue\n"),
        "{header}"
    );
    for file in [&pts, &mesh] {
        let cloud = read_ply(file).unwrap();
        let channel =
            |name: &str| match &cloud.extras.iter().find(|e| e.name == name).unwrap().values {
                ExtraValues::UChar(v) => v.clone(),
                other => panic!("{name}: {other:?}"),
            };
        let (r, gr, b) = (channel("red"), channel("green"), channel("blue"));
        assert!(cloud.points.len() > 100);
        let mut reds = std::collections::BTreeSet::new();
        for (i, p) in cloud.points.iter().enumerate() {
            // Blender units → the grid's world (× 2/3) → grid coordinates.
            let gx = g.world_to_grid(p.map(|c| c * 2.0 / 3.0))[0];
            let want = 255.0 * gx / top;
            assert!(
                (r[i] as f32 - want).abs() <= 2.0,
                "{}: point {p:?}: red {} vs {want}",
                file.display(),
                r[i]
            );
            assert_eq!((gr[i], b[i]), (128, 230), "{}", file.display());
            reds.insert(r[i]);
        }
        assert!(reds.len() > 20, "red varies over the sphere: {reds:?}");
    }
}

#[test]
fn extract_then_eval_end_to_end() {
    let dir = tempfile::tempdir().unwrap();
    // Density 100 at the centre falling off with distance: σ = 50 on a sphere of radius 5 voxel.
    let g = sphere_grid();
    let ckpt = dir.path().join("ckpt.npz");
    npz::save_svox2(&g, &ckpt).unwrap();
    // GT: the sphere σ = 50 in Blender units (radius 5 voxel = 5 · 2/20 scene = 0.5 scene).
    let gt: Vec<[f32; 3]> = {
        let centre = g.grid_to_world([10.0; 3]).map(|x| x * 1.5);
        let mut rng = Pcg64::seed_from_u64(1);
        (0..50000)
            .map(|_| {
                let v = [0; 3].map(|_| rng.random_range(-1.0f32..1.0));
                let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-6);
                std::array::from_fn(|k| centre[k] + 0.75 * v[k] / n)
            })
            .collect()
    };
    let gt_path = dir.path().join("gt.ply");
    write_points(&gt_path, &gt).unwrap();
    for backend in ["cpu", "vulkan"] {
        let out_ply = dir.path().join(format!("pts_{backend}.ply"));
        let out = bin()
            .args([
                "extract",
                "--levels",
                "50",
                "--json",
                "--backend",
                backend,
                "--ckpt",
            ])
            .arg(&ckpt)
            .arg("--out")
            .arg(&out_ply)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let stdout = String::from_utf8_lossy(&out.stdout);
        let j: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap()).unwrap();
        assert!(j["points"].as_u64().unwrap() > 1000, "{j}");
        let cloud = read_ply(&out_ply).unwrap();
        let names: Vec<&str> = cloud.extras.iter().map(|e| e.name.as_str()).collect();
        assert_eq!(
            names,
            ["level", "alpha", "nx", "ny", "nz", "red", "green", "blue"]
        );
        let out = eval_cmd(&out_ply, &gt_path);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let stdout = String::from_utf8_lossy(&out.stdout);
        let j: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap()).unwrap();
        let chamfer = j["metrics"]["chamfer"].as_f64().unwrap();
        let f1 = j["metrics"]["f1"].as_f64().unwrap();
        assert!(chamfer.is_finite() && chamfer < 0.02, "{j}");
        assert!(f1 > 0.3 && f1 <= 1.0, "{j}");
    }
    // A run directory without a checkpoint is a clear error.
    let out = bin()
        .args(["extract", "--backend", "cpu", "--run"])
        .arg(dir.path())
        .arg("--out")
        .arg(dir.path().join("x.ply"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("plenoxels.npz"));
}

/// A capture's prediction holds the floor too; its GT is the object alone. `eval` scores only
/// the predicted points inside the scene.json's `eval_box` (next to the GT) or `--box`: the
/// floor is not scored as the object, and is counted as left out; without a box it costs the
/// Chamfer distance. `extract --box` keeps only the points and faces inside its box.
#[test]
fn eval_and_extract_score_within_a_box() {
    let dir = tempfile::tempdir().unwrap();
    let object: Vec<[f32; 3]> = (0..2000)
        .map(|i| {
            let a = i as f32 * 0.01;
            [0.3 * a.cos(), 0.3 * a.sin(), -0.5 + i as f32 / 2000.0]
        })
        .collect();
    let floor: Vec<[f32; 3]> = (0..2000)
        .map(|i| {
            [
                (i % 50) as f32 * 0.05 - 1.25,
                (i / 50) as f32 * 0.05 - 1.0,
                -0.6,
            ]
        })
        .collect();
    let (gt, pred) = (dir.path().join("gt.ply"), dir.path().join("pred.ply"));
    write_points(&gt, &object).unwrap();
    write_points(&pred, &[object.clone(), floor].concat()).unwrap();
    let chamfer = |extra: &[&str]| -> (f64, serde_json::Value) {
        let out = eval_exact(&pred, &gt, extra);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let text = String::from_utf8_lossy(&out.stdout);
        let j: serde_json::Value = serde_json::from_str(text.lines().last().unwrap()).unwrap();
        (
            j["metrics"]["chamfer"].as_f64().unwrap(),
            j["eval_box"].clone(),
        )
    };
    let (all, no_box) = chamfer(&[]);
    assert!(no_box.is_null());
    std::fs::write(
        dir.path().join("scene.json"),
        r#"{"eval_box": {"min": [-0.4, -0.4, -0.55], "max": [0.4, 0.4, 0.55]}}"#,
    )
    .unwrap();
    let (boxed, b) = chamfer(&[]);
    assert!(
        all > 0.05 && boxed < 1e-6,
        "Chamfer {all} with the floor, {boxed} without"
    );
    assert_eq!(b["pred_outside"].as_u64(), Some(2000), "{b}");
    assert!(b["from"].as_str().unwrap().ends_with("scene.json"), "{b}");
    // --box wins over the scene's; a box holding no predicted point is an error naming it.
    let (_, b) = chamfer(&["--box", "-0.41,-0.41,-0.7,0.41,0.41,0.55"]);
    assert_eq!(
        (b["from"].as_str(), b["pred_outside"].as_u64()),
        (Some("--box"), Some(2000 - 17 * 17))
    );
    let out = eval_exact(&pred, &gt, &["--box", "5,5,5,6,6,6"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("evaluation box"),
        "{err}"
    );
    let out = eval_exact(&pred, &gt, &["--box", "1,0,0,0,1,1"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("--box") && err.contains("below"),
        "{err}"
    );

    // extract --box on the analytic sphere (centre 10 voxels = Blender (0.15, -0.075, 0)): only
    // the upper half, z ≥ 0, is kept, in the points and the mesh.
    let g = sphere_grid();
    let (pts, mesh) = extract_points_and_mesh(dir.path(), &g, &["--box", "-2,-2,0,2,2,2"]);
    for file in [&pts, &mesh] {
        let p = read_ply(file).unwrap().points;
        assert!(p.len() > 100, "{}", file.display());
        let low = p.iter().filter(|q| q[2] < 0.0).count();
        let high = p.iter().filter(|q| q[2] > 0.2).count();
        // Mesh faces are kept by centroid: a vertex may lie up to a cell (0.15) below z = 0.
        assert!(
            p.iter().all(|q| q[2] >= -0.16) && high > 10 * low,
            "{}: {low} points below z = 0",
            file.display()
        );
    }
}

/// A 1-D `.npy` file of `data`.
fn write_npy<T: npyz::AutoSerialize + Copy>(path: &Path, data: &[T]) {
    use npyz::WriterBuilder;
    let mut out = Vec::new();
    let mut w = npyz::WriteOptions::new()
        .default_dtype()
        .shape(&[data.len() as u64])
        .writer(&mut out)
        .begin_nd()
        .unwrap();
    w.extend(data.iter().copied()).unwrap();
    w.finish().unwrap();
    std::fs::write(path, out).unwrap();
}

#[test]
fn eval_counts_completeness_over_the_visible_gt_points() {
    let dir = tempfile::tempdir().unwrap();
    // GT: a front sheet the prediction covers and a back sheet it misses (never seen).
    let sheet = |z: f32| -> Vec<[f32; 3]> {
        (0..1600)
            .map(|i| [(i % 40) as f32 * 0.01, (i / 40) as f32 * 0.01, z])
            .collect()
    };
    let (front, back) = (sheet(0.0), sheet(0.2));
    let (gt, pred) = (dir.path().join("gt.ply"), dir.path().join("pred.ply"));
    write_points(&gt, &[front.clone(), back.clone()].concat()).unwrap();
    write_points(&pred, &front).unwrap();
    let seen: Vec<bool> = (0..3200).map(|i| i < 1600).collect();
    let mask = dir.path().join("visible.npy");
    write_npy(&mask, &seen);
    let run = |extra: &[&std::ffi::OsStr]| eval_exact(&pred, &gt, extra);
    let metrics = |out: &std::process::Output| -> serde_json::Value {
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let text = String::from_utf8_lossy(&out.stdout);
        serde_json::from_str(text.lines().last().unwrap()).unwrap()
    };
    let all = metrics(&run(&[]));
    let visible = metrics(&run(&["--visible".as_ref(), mask.as_os_str()]));
    // Without the mask the back sheet is half the GT and 0.2 from the prediction.
    assert!((all["metrics"]["recall"].as_f64().unwrap() - 0.5).abs() < 1e-9);
    assert!((all["metrics"]["mean_s2d"].as_f64().unwrap() - 0.1).abs() < 1e-6);
    // With it completeness counts the front sheet only; accuracy is unchanged.
    assert_eq!(visible["metrics"]["recall"].as_f64().unwrap(), 1.0);
    assert_eq!(visible["metrics"]["mean_s2d"].as_f64().unwrap(), 0.0);
    assert_eq!(visible["metrics"]["n_gt"].as_u64().unwrap(), 1600);
    assert_eq!(visible["visible"]["gt_scored"].as_u64().unwrap(), 1600);
    assert_eq!(visible["metrics"]["mean_d2s"], all["metrics"]["mean_d2s"]);
    // A forward-facing capture's scene.json names its mask: used by default; an orbit's is not.
    let scene = dir.path().join("scene.json");
    for (layout, recall) in [("forward", 1.0), ("orbit", 0.5)] {
        let meta = serde_json::json!({"layout": layout, "visibility": {"file": "visible.npy"}});
        std::fs::write(&scene, meta.to_string()).unwrap();
        let m = metrics(&run(&[]));
        assert!(
            (m["metrics"]["recall"].as_f64().unwrap() - recall).abs() < 1e-9,
            "{layout}"
        );
    }
    std::fs::remove_file(&scene).unwrap();
    // A mask of another length, or not boolean, is an error naming the file.
    write_npy(&mask, &seen[..100]);
    let out = run(&["--visible".as_ref(), mask.as_os_str()]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("visible.npy") && err.contains("100 flags"),
        "{err}"
    );
    let floats = dir.path().join("floats.npy");
    write_npy(&floats, &vec![1.0f32; 3200]);
    let out = run(&["--visible".as_ref(), floats.as_os_str()]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("floats.npy") && err.contains("dtype"),
        "{err}"
    );
}
