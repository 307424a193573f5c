//! `extract --mesh` end to end on both built-in scenes at a small size: stage 1 and stage 2 are
//! trained (`train --stage all`, 64³), each grid is extracted as points and as a mesh, the mesh is
//! read back by a PLY reader written here (independent of the crate's writer and of `ply-rs-bw`)
//! and checked (finite, valid indices, unit normals, levels and α), and points drawn uniformly by
//! area on it have a Chamfer distance within 5 % of the point cloud's. Training runs on one rayon
//! thread so that every figure is fixed (with several, the order of the float atomic adds varies
//! and the thin scene's gaps ranged from −3.2 % to −4.8 % over runs); the fixed gaps are −3.3 %,
//! −2.9 % (thin, stages 1 and 2), +0.7 %, +1.1 % (translucent).
//!
//! The point clouds use 9² rays per axis and cell: their ray spacing at 64³, 3/64/8 Blender units,
//! is the default extraction's at 128³ (5² rays), where the demo's figures are taken. With 5² rays
//! at 64³ the point cloud is a coarser, orientation-weighted sample of the same surfaces (each
//! axis's rays find a surface in proportion to its projected area), and its Chamfer on the thin
//! scene's stage 2 is up to 6 % above the mesh's.

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

/// The last stdout line that is a JSON object.
fn last_json(text: &str) -> serde_json::Value {
    serde_json::from_str(
        text.lines()
            .rfind(|l| l.starts_with('{'))
            .expect("a JSON line"),
    )
    .expect("valid JSON")
}

/// A mesh as read here: per-vertex float properties by name, and triangles.
struct PlyMesh {
    props: Vec<(String, Vec<f32>)>,
    faces: Vec<[u32; 3]>,
}

impl PlyMesh {
    fn prop(&self, name: &str) -> &[f32] {
        &self
            .props
            .iter()
            .find(|(n, _)| n == name)
            .unwrap_or_else(|| panic!("no vertex property {name}"))
            .1
    }
    fn position(&self, i: usize) -> [f64; 3] {
        ["x", "y", "z"].map(|a| self.prop(a)[i] as f64)
    }
}

/// A minimal reader for binary little-endian PLY with float and uchar vertex properties (uchar
/// read as its value) and a face element of `list uchar int|uint vertex_indices` (what
/// `extract --mesh` promises to write).
fn read_ply_mesh(path: &Path) -> PlyMesh {
    let bytes = std::fs::read(path).unwrap();
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .expect("end_header")
        + 11;
    let header = std::str::from_utf8(&bytes[..end]).unwrap();
    let mut lines = header.lines();
    assert_eq!(lines.next(), Some("ply"));
    let (mut nv, mut nf, mut element) = (0usize, 0usize, "");
    let mut names = Vec::new();
    for line in lines {
        let w: Vec<&str> = line.split_whitespace().collect();
        match w.as_slice() {
            ["format", f, "1.0"] => assert_eq!(*f, "binary_little_endian"),
            ["element", "vertex", n] => (element, nv) = ("vertex", n.parse().unwrap()),
            ["element", "face", n] => (element, nf) = ("face", n.parse().unwrap()),
            ["property", "float", name] if element == "vertex" => names.push((name.to_string(), 4)),
            ["property", "uchar", name] if element == "vertex" => names.push((name.to_string(), 1)),
            ["property", "list", "uchar", "int" | "uint", "vertex_indices"] => {
                assert_eq!(element, "face")
            }
            ["comment", ..] | ["end_header"] => {}
            other => panic!("unexpected header line {other:?}"),
        }
    }
    let value_at = |o: usize, size: usize| match size {
        4 => f32::from_le_bytes(bytes[o..o + 4].try_into().unwrap()),
        _ => bytes[o] as f32,
    };
    let mut props: Vec<(String, Vec<f32>)> = names.iter().map(|n| (n.0.clone(), vec![])).collect();
    let stride: usize = names.iter().map(|n| n.1).sum();
    for i in 0..nv {
        let mut o = end + i * stride;
        for (p, (_, size)) in props.iter_mut().zip(&names) {
            p.1.push(value_at(o, *size));
            o += size;
        }
    }
    let mut o = end + nv * stride;
    let mut faces = Vec::with_capacity(nf);
    for _ in 0..nf {
        assert_eq!(bytes[o], 3, "a face that is not a triangle");
        let idx: [u32; 3] = std::array::from_fn(|k| {
            u32::from_le_bytes(bytes[o + 1 + 4 * k..o + 5 + 4 * k].try_into().unwrap())
        });
        faces.push(idx);
        o += 13;
    }
    assert_eq!(o, bytes.len(), "bytes after the faces");
    PlyMesh { props, faces }
}

/// `n` points uniformly by area on the mesh (face by area, then a uniform point in it), from a
/// small xorshift generator of our own.
fn sample(m: &PlyMesh, n: usize) -> Vec<[f32; 3]> {
    let mut cdf = Vec::with_capacity(m.faces.len());
    let mut total = 0.0;
    for f in &m.faces {
        let [a, b, c] = f.map(|i| m.position(i as usize));
        let (u, v) = (
            [b[0] - a[0], b[1] - a[1], b[2] - a[2]],
            [c[0] - a[0], c[1] - a[1], c[2] - a[2]],
        );
        let x = [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ];
        total += 0.5 * (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt();
        cdf.push(total);
    }
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut uniform = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..n)
        .map(|_| {
            let r = uniform() * total;
            let fi = cdf.partition_point(|&c| c <= r).min(cdf.len() - 1);
            let [a, b, c] = m.faces[fi].map(|i| m.position(i as usize));
            let (mut s, mut t) = (uniform(), uniform());
            if s + t > 1.0 {
                (s, t) = (1.0 - s, 1.0 - t);
            }
            std::array::from_fn(|k| (a[k] + s * (b[k] - a[k]) + t * (c[k] - a[k])) as f32)
        })
        .collect()
}

fn chamfer(pred: &Path, gt: &Path, extra: &[&str]) -> f64 {
    let text = run_ok(
        bin()
            .args(["eval", "--json", "--pred"])
            .arg(pred)
            .arg("--gt")
            .arg(gt)
            .args(extra),
    );
    last_json(&text)["metrics"]["chamfer"].as_f64().unwrap()
}

/// Train both stages on a built-in scene; returns (scene dir, run dir).
fn trained(dir: &Path, kind: &str) -> (PathBuf, PathBuf) {
    let data = dir.join(format!("{kind}-scene"));
    run_ok(
        bin()
            .args(["make-scene", "--kind", kind, "--res", "96", "--views", "32"])
            .args(["--spp", "1", "--gt-spacing", "0.01", "--out"])
            .arg(&data),
    );
    let out = dir.join(format!("{kind}-run"));
    // One rayon thread: CPU training with several is not bit-reproducible (the order of the
    // float atomic adds varies), and the Chamfer comparison below needs a fixed figure.
    run_ok(
        bin()
            .env("RAYON_NUM_THREADS", "1")
            .args(["train", "--stage", "all", "--data"])
            .arg(&data)
            .arg("--out")
            .arg(&out)
            .args([
                "--backend",
                "cpu",
                "--quiet",
                "--batch",
                "2048",
                "--res",
                "64",
            ])
            .args([
                "--iters",
                "600",
                "--surface-iters",
                "200",
                "--category",
                kind,
            ]),
    );
    (data, out)
}

/// Extract `run` as points and as a mesh, check the mesh, compare the Chamfer distances.
fn check_stage(dir: &Path, gt: &Path, run: &Path, levels: Option<&str>, name: &str) {
    let (pts, mesh) = (
        dir.join(format!("{name}-points.ply")),
        dir.join(format!("{name}-mesh.ply")),
    );
    let mut cmd = bin();
    cmd.args([
        "extract",
        "--backend",
        "cpu",
        "--rays-per-axis",
        "9",
        "--json",
        "--run",
    ])
    .arg(run)
    .arg("--out")
    .arg(&pts)
    .arg("--mesh")
    .arg(&mesh);
    if let Some(l) = levels {
        cmd.args(["--levels", l]);
    }
    let j = last_json(&run_ok(&mut cmd));
    // Hidden surfaces and the outermost level's halo are trimmed by default on stage-2 thin runs
    // only, from points and mesh; thin sheets' points are centred on those runs too.
    let trimmed = name == "thin-surface";
    for key in [
        "hidden",
        "mesh_hidden",
        "outer_dropped",
        "mesh_outer_dropped",
        "sheets_moved",
    ] {
        assert_eq!(!j[key].is_null(), trimmed, "{name}: {key} {}", j[key]);
    }
    let n_points = j["points"].as_u64().unwrap() as usize;
    let m = read_ply_mesh(&mesh);
    let nv = m.prop("x").len();
    assert_eq!(j["mesh_stats"]["vertices"].as_u64(), Some(nv as u64));
    assert_eq!(
        j["mesh_stats"]["faces"].as_u64(),
        Some(m.faces.len() as u64)
    );
    assert!(m.faces.len() > 1000, "{name}: {} faces", m.faces.len());
    for (p, v) in &m.props {
        assert!(v.iter().all(|x| x.is_finite()), "{name}: non-finite {p}");
    }
    let mut used = vec![false; nv];
    for f in &m.faces {
        assert!(f.iter().all(|&i| (i as usize) < nv), "{name}: face {f:?}");
        assert!(
            f[0] != f[1] && f[1] != f[2] && f[0] != f[2],
            "{name}: face {f:?}"
        );
        f.iter().for_each(|&i| used[i as usize] = true);
    }
    assert!(used.iter().all(|&u| u), "{name}: unused vertices");
    // Welded: an unwelded mesh repeats each vertex in every face around it (about 6 times).
    // A few distinct edge crossings may still round to one f32 position (a crossing within
    // ~1e-7 of a cell of a grid vertex whose value is not exactly τ), so a handful is allowed.
    let mut keys: Vec<[u32; 4]> = (0..nv)
        .map(|i| ["x", "y", "z", "level"].map(|p| m.prop(p)[i].to_bits()))
        .collect();
    keys.sort_unstable();
    keys.dedup();
    assert!(
        (nv - keys.len()) * 10_000 < nv,
        "{name}: {} of {nv} vertices repeat a position",
        nv - keys.len()
    );
    for i in 0..nv {
        let n = ["nx", "ny", "nz"].map(|p| m.prop(p)[i] as f64);
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        assert!(
            len == 0.0 || (len - 1.0).abs() < 1e-4,
            "{name}: normal {n:?}"
        );
        assert!((0.0..=1.0).contains(&m.prop("alpha")[i]));
    }
    // Coloured: the surface colour varies over the object.
    let reds: std::collections::BTreeSet<u32> = m.prop("red").iter().map(|&r| r as u32).collect();
    assert!(reds.len() > 10, "{name}: red takes {} values", reds.len());
    let want: Vec<f32> = j["levels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap() as f32)
        .collect();
    assert!(m.prop("level").iter().all(|l| want.contains(l)));

    // Chamfer: the point cloud, then as many points drawn on the mesh here, then by `eval`.
    let c_points = chamfer(&pts, gt, &[]);
    let drawn = dir.join(format!("{name}-drawn.ply"));
    alphasurf::io::write_points(&drawn, &sample(&m, n_points)).unwrap();
    let c_mesh = chamfer(&drawn, gt, &[]);
    let n = n_points.to_string();
    let c_eval = chamfer(&mesh, gt, &["--mesh-samples", &n]);
    println!(
        "{name}: Chamfer points {c_points:.7}, mesh {c_mesh:.7} ({:+.2} %; eval {c_eval:.7})",
        100.0 * (c_mesh / c_points - 1.0)
    );
    assert!(
        (c_mesh / c_points - 1.0).abs() < 0.05,
        "{name}: mesh Chamfer {c_mesh} vs points {c_points}"
    );
    // The same distribution drawn by `eval` from the crate's reader: equal up to sampling noise.
    assert!(
        (c_eval / c_mesh - 1.0).abs() < 0.01,
        "{name}: eval's mesh Chamfer {c_eval} vs {c_mesh}"
    );
}

#[test]
fn meshes_of_both_stages_match_the_point_clouds() {
    let dir = tempfile::tempdir().unwrap();
    for kind in ["thin", "translucent"] {
        let (data, run) = trained(dir.path(), kind);
        let gt = data.join("gt_points.ply");
        check_stage(
            dir.path(),
            &gt,
            &run.join("plenoxels"),
            Some("10,50"),
            &format!("{kind}-plenoxels"),
        );
        check_stage(
            dir.path(),
            &gt,
            &run.join("surface"),
            None,
            &format!("{kind}-surface"),
        );
    }
}

#[test]
fn mesh_flag_errors() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("scene");
    run_ok(
        bin()
            .args([
                "make-scene",
                "--kind",
                "thin",
                "--res",
                "32",
                "--views",
                "8",
            ])
            .args(["--spp", "1", "--gt-spacing", "0.05", "--out"])
            .arg(&data),
    );
    let out = dir.path().join("run");
    run_ok(
        bin()
            .args(["train", "--data"])
            .arg(&data)
            .arg("--out")
            .arg(&out)
            .args([
                "--backend",
                "cpu",
                "--quiet",
                "--res",
                "32",
                "--iters",
                "50",
            ]),
    );
    // Neither --out nor --mesh; the same file for both; a level no surface has.
    let (ok, text) = run(bin().args(["extract", "--run"]).arg(&out));
    assert!(
        !ok && text.contains("required") && text.contains("--out"),
        "{text}"
    );
    let same = dir.path().join("a.ply");
    let (ok, text) = run(bin()
        .args(["extract", "--backend", "cpu", "--run"])
        .arg(&out)
        .arg("--out")
        .arg(&same)
        .arg("--mesh")
        .arg(&same));
    assert!(!ok && text.contains("same file"), "{text}");
    let mesh = dir.path().join("m.ply");
    let (ok, text) = run(bin()
        .args(["extract", "--backend", "cpu", "--levels", "1e9", "--run"])
        .arg(&out)
        .arg("--mesh")
        .arg(&mesh));
    assert!(!ok && text.contains("no surface faces"), "{text}");
    assert!(!mesh.exists());
    // A mesh alone (no --out) is written and is a mesh to `eval`.
    run_ok(
        bin()
            .args(["extract", "--backend", "cpu", "--levels", "5", "--run"])
            .arg(&out)
            .arg("--mesh")
            .arg(&mesh),
    );
    let text = run_ok(
        bin()
            .args(["eval", "--mesh-samples", "5000", "--pred"])
            .arg(&mesh)
            .arg("--gt")
            .arg(data.join("gt_points.ply")),
    );
    assert!(text.contains("drew 5000 points"), "{text}");
}
