//! Generated scenes: they load as NeRF-synthetic datasets, their ground truth projects onto
//! their alpha masks (camera convention), re-rendering a view reproduces the written PNG,
//! generation is deterministic for a seed, and the scenes meet their specification.

use alphasurf::data::{Dataset, LoadOptions};
use alphasurf::scene::render::trace;
use alphasurf::scene::{build, generate, render_view, GenerateOptions, SceneKind, Shape};
use glam::{DVec3, Vec3};
use std::path::Path;

const KINDS: [SceneKind; 3] = [SceneKind::Thin, SceneKind::Translucent, SceneKind::Solid];

fn small(kind: SceneKind, seed: u64) -> GenerateOptions {
    GenerateOptions {
        res: 64,
        views: 5,
        seed,
        spp_side: 4,
        gt_spacing: 0.006,
        ..GenerateOptions::new(kind)
    }
}

fn make(kind: SceneKind, seed: u64) -> tempfile::TempDir {
    let d = tempfile::tempdir().unwrap();
    generate(d.path(), &small(kind, seed)).unwrap();
    d
}

#[test]
fn generated_scene_loads_and_gt_lands_on_alpha() {
    for kind in KINDS {
        let d = make(kind, 3);
        let ds = Dataset::load(d.path(), &LoadOptions::default()).unwrap();
        assert_eq!(ds.train.frames.len(), 5);
        assert_eq!(ds.val().frames.len(), 1);
        assert_eq!(ds.test.frames.len(), 1);
        assert_eq!((ds.train.width(), ds.train.height()), (64, 64));
        for f in ds.splits().iter().flat_map(|s| &s.frames) {
            assert!((f.camera.centre().length() - 4.0).abs() < 1e-4);
            assert!(
                f.camera.forward().dot(-f.camera.centre().normalize()) > 0.9999,
                "looks at the origin"
            );
            assert!(f.image.had_alpha);
        }
        let pts = alphasurf::io::read_points(&d.path().join("gt_points.ply")).unwrap();
        assert!(pts.iter().all(|p| p.iter().all(|v| v.abs() <= 1.5)));
        let (mut landed, mut total) = (0, 0);
        for f in ds.train.frames.iter().chain(&ds.test.frames) {
            for p in pts.iter().step_by(7) {
                total += 1;
                if let Some((x, y, _)) = f.camera.project(Vec3::from_array(*p)) {
                    if x >= 0.0
                        && y >= 0.0
                        && x < 64.0
                        && y < 64.0
                        && f.image.alpha(x as u32, y as u32) > 0.0
                    {
                        landed += 1;
                    }
                }
            }
        }
        let frac = landed as f64 / total as f64;
        eprintln!(
            "{kind:?}: {:.2}% of gt points land on alpha > 0",
            100.0 * frac
        );
        assert!(
            frac >= 0.95,
            "{kind:?}: only {:.2}% of gt points land on alpha > 0",
            100.0 * frac
        );
        let inspect = alphasurf::data::inspect::inspect(&ds);
        assert!(inspect.object_bounds.is_some());
    }
}

fn decode(path: &Path) -> Vec<u8> {
    image::open(path).unwrap().to_rgba8().into_raw()
}

#[test]
fn rerendering_a_view_reproduces_the_png() {
    for kind in KINDS {
        let d = make(kind, 5);
        let ds = Dataset::load(d.path(), &LoadOptions::default()).unwrap();
        let scene = build(kind, 5);
        for (split, view) in [(&ds.train, 2), (&ds.test, 0)] {
            let f = &split.frames[view];
            let again = render_view(&scene, &f.camera, 4);
            assert!(
                again == decode(&f.file),
                "{kind:?} {}: re-render differs",
                f.file.display()
            );
        }
    }
}

fn all_files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    for sub in ["", "train", "val", "test"] {
        let mut names: Vec<_> = std::fs::read_dir(dir.join(sub))
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        names.sort();
        for p in names.into_iter().filter(|p| p.is_file()) {
            let name = p.strip_prefix(dir).unwrap().display().to_string();
            let mut bytes = std::fs::read(&p).unwrap();
            if name == "scene.json" {
                let mut v: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
                v.as_object_mut().unwrap().remove("timing_s");
                bytes = v.to_string().into_bytes();
            }
            out.push((name, bytes));
        }
    }
    out
}

#[test]
fn deterministic_for_a_seed() {
    let (a, b, c) = (
        make(SceneKind::Thin, 9),
        make(SceneKind::Thin, 9),
        make(SceneKind::Thin, 10),
    );
    let (fa, fb, fc) = (
        all_files(a.path()),
        all_files(b.path()),
        all_files(c.path()),
    );
    assert_eq!(fa.len(), 5 + 1 + 1 + 3 + 2);
    for ((na, ba), (nb, bb)) in fa.iter().zip(&fb) {
        assert_eq!(na, nb);
        assert!(ba == bb, "{na} differs between two runs with the same seed");
    }
    let png = |f: &[(String, Vec<u8>)]| {
        f.iter()
            .find(|(n, _)| n == "train/r_0.png")
            .unwrap()
            .1
            .clone()
    };
    assert_ne!(png(&fa), png(&fc), "another seed gives other cameras");
}

#[test]
fn scenes_fit_the_box_and_meet_their_spec() {
    for kind in KINDS {
        for seed in 0..5 {
            let s = build(kind, seed);
            let (lo, hi) = s.aabb();
            assert!(
                lo.min_element() >= -1.5 && hi.max_element() <= 1.5,
                "{kind:?} seed {seed}: {lo} {hi}"
            );
            assert!(
                lo.min_element() < -0.5 && hi.max_element() > 0.5,
                "{kind:?} should fill the box"
            );
        }
    }
    let thin = build(SceneKind::Thin, 0);
    let wires: Vec<_> = thin
        .objects
        .iter()
        .filter(|o| o.name.starts_with("wire"))
        .collect();
    assert!(wires.len() >= 8);
    for w in wires {
        let Shape::Capsule { radius, .. } = w.shape else {
            panic!("wires are capsules")
        };
        assert!(2.0 * radius <= 0.03, "wire thicker than 1/100 of the scene");
    }
    assert!(
        thin.objects
            .iter()
            .filter(|o| matches!(o.shape, Shape::Ellipse { .. }))
            .count()
            >= 10,
        "zero-thickness leaves"
    );
    let tr = build(SceneKind::Translucent, 0);
    let shells: Vec<_> = tr.objects.iter().filter(|o| !o.opaque()).collect();
    assert!(shells.len() >= 2 && tr.objects.iter().any(|o| o.opaque()));
    assert!(build(SceneKind::Solid, 0)
        .objects
        .iter()
        .all(|o| o.opaque()));
}

#[test]
fn semi_transparent_shells_composite_in_depth_order() {
    let s = build(SceneKind::Translucent, 0);
    let all: Vec<u32> = (0..s.objects.len() as u32).collect();
    let mut hits = Vec::new();
    // Through the outer shell only (twice): coverage 1 − 0.7².
    let (o, d) = (DVec3::new(0.0, -4.0, 0.80), DVec3::Y);
    let (c, a) = trace(&s, &all, o, d, &mut hits);
    assert_eq!(hits.len(), 2);
    assert!((a - (1.0 - 0.7 * 0.7)).abs() < 1e-12, "coverage {a}");
    let sh = |t: f64| {
        let p = o + t * d;
        let n = (p - DVec3::new(0.0, 0.0, 0.05)) / 0.85;
        s.objects[0].material.shade(p, n, d, s.light)
    };
    let want = 0.3 * sh(hits[0].0) + 0.7 * 0.3 * sh(hits[1].0);
    assert!((c - want).length() < 1e-12);
    // Through the centre: outer, inner, then the opaque toy stops the ray: full coverage.
    let (c2, a2) = trace(&s, &all, DVec3::new(0.0, -4.0, 0.0), DVec3::Y, &mut hits);
    assert!(hits.len() >= 5 && (a2 - 1.0).abs() < 1e-12 && c2.min_element() >= 0.0);
}

#[test]
fn gt_covers_every_surface_including_inner_shells() {
    let d = tempfile::tempdir().unwrap();
    let opts = GenerateOptions {
        res: 16,
        views: 1,
        spp_side: 1,
        gt_spacing: 0.004,
        ..GenerateOptions::new(SceneKind::Translucent)
    };
    generate(d.path(), &opts).unwrap();
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.path().join("scene.json")).unwrap())
            .unwrap();
    let pts = alphasurf::io::read_points(&d.path().join("gt_points.ply")).unwrap();
    assert_eq!(v["gt"]["n_points"].as_u64().unwrap() as usize, pts.len());
    let mut next = 0;
    for o in v["objects"].as_array().unwrap() {
        let (start, count) = (
            o["point_start"].as_u64().unwrap() as usize,
            o["point_count"].as_u64().unwrap() as usize,
        );
        assert_eq!(start, next);
        next += count;
        // Density: about one point per spacing² of exposed area (buried parts are dropped).
        let full = (o["area"].as_f64().unwrap() / (0.004f64 * 0.004)).ceil() as usize;
        assert!(
            count <= full && count > 0,
            "{}: {count} of {full}",
            o["name"]
        );
        if o["kind"] == "translucent" {
            assert_eq!(count, full, "shells are never buried");
        }
    }
    assert_eq!(next, pts.len());
    // Inner shell points lie on its sphere.
    let inner = v["objects"]
        .as_array()
        .unwrap()
        .iter()
        .find(|o| o["name"] == "shell_inner")
        .unwrap();
    let c = DVec3::new(0.03, -0.02, 0.0);
    let s = inner["point_start"].as_u64().unwrap() as usize;
    for p in &pts[s..s + 100] {
        assert!(((Vec3::from_array(*p).as_dvec3() - c).length() - 0.55).abs() < 1e-6);
    }
}
