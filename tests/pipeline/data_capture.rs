//! Captures as they arrive (`../shared/fixtures/capture_*`: an object in a room, COLMAP text
//! model, no masks, no split file): the foreground box found from the cameras and sparse points,
//! and the split stated.

use crate::data_common::shared_fixture;
use alphasurf::abi::rays::key_pixel;
use alphasurf::cpu::sample_rays::sample_rays;
use alphasurf::data::inspect::inspect;
use alphasurf::data::ndc::Space;
use alphasurf::data::Aabb;
use alphasurf::data::{BackgroundMode, Dataset, LoadOptions, SplitRule, TrainViews};
use alphasurf::grid::InitialFill;
use alphasurf::pipeline::train_plenoxels::initial_fill;
use glam::Vec3;

/// The object's box from the fixture's `scene.json` (`bbox_min`, `bbox_max`).
fn object_box(dir: &std::path::Path) -> (Vec3, Vec3) {
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("scene.json")).unwrap()).unwrap();
    let v = |k: &str| {
        let a: Vec<f32> = serde_json::from_value(meta[k].clone()).unwrap();
        Vec3::from_slice(&a)
    };
    (v("bbox_min"), v("bbox_max"))
}

/// On the 360° birdcage and the forward-facing fan, the foreground box found from the cameras
/// contains the object and is at most twice its size per axis (the sparse points' 1st–99th
/// percentile box was the room: −8.8 … 10.8 units around a 1.04-unit cage); the scene box is the
/// cube around it; the split is every 8th image.
#[test]
fn capture_foreground_box_bounds_the_object() {
    for name in ["capture_birdcage", "capture_fan_ff"] {
        let dir = shared_fixture(name);
        let ds = Dataset::load(&dir, &LoadOptions::default()).unwrap();
        let fg = ds.foreground.as_ref().expect("a foreground box");
        let (fmin, fmax) = (fg.bounds.lo(), fg.bounds.hi());
        let (lo, hi) = object_box(&dir);
        assert!(
            fmin.cmple(lo).all() && fmax.cmpge(hi).all(),
            "{name}: foreground box {:?}..{:?} does not contain the object {lo:?}..{hi:?}",
            fmin,
            fmax
        );
        let ratio = (fmax - fmin) / (hi - lo);
        assert!(
            ratio.max_element() <= 2.0,
            "{name}: foreground box {:?}..{:?} is {ratio:?} × the object's size",
            fmin,
            fmax
        );
        assert!(fg.how.contains("converge"), "{}", fg.how);
        // The grid cube is the box's, widened to its widest side.
        let (bmin, bmax) = ds.scene.blender_bounds();
        assert!(bmin.cmple(fmin + 1e-4).all() && bmax.cmpge(fmax - 1e-4).all());
        assert!(((bmax - bmin).max_element() - (fmax - fmin).max_element()).abs() < 1e-3);
        assert_eq!(ds.split_rule, SplitRule::EveryNth(8));
        let n = ds.train.frames.len() + ds.test.frames.len();
        assert_eq!(ds.test.frames.len(), n.div_ceil(8), "{name}");
        object_is_allocated(&ds, (lo, hi));
    }
}

/// A new stage-1 grid on a capture in its foreground box allocates the whole box: the corners of
/// the birdcage's plinth (its rim on the floor) lie outside the grid's inscribed sphere. In NDC,
/// and in a box given with `--box`, the inscribed sphere.
fn object_is_allocated(ds: &Dataset, (lo, hi): (Vec3, Vec3)) {
    let scene = &ds.scene;
    let says = inspect(ds)
        .to_string()
        .contains("starts with all of it allocated");
    if scene.ndc.is_some() {
        assert!(initial_fill(ds) == InitialFill::Sphere && !says);
        return;
    }
    assert!(initial_fill(ds) == InitialFill::Box && says);
    let rim = scene.to_scaled(Vec3::new(hi.x, 0.5 * (lo.y + hi.y), lo.z));
    assert!((rim - scene.centre).length() > scene.radius * InitialFill::Sphere.radius());
    let given = Dataset::load(
        &ds.root,
        &LoadOptions {
            scene: Some(Aabb::new(lo - 0.5, hi + 0.5).scene_box()),
            ..LoadOptions::default()
        },
    )
    .unwrap();
    assert_eq!(initial_fill(&given), InitialFill::Sphere);
}

/// The LLFF layout of the same capture (`poses_bounds.npy` beside `images/`, no COLMAP model)
/// loads the same views as the COLMAP model: same poses (to f32 rounding), intrinsics, pixels and
/// split; its box is found from the cameras alone (no sparse points) and still holds the object.
#[test]
fn llff_poses_bounds_load_as_the_colmap_model_does() {
    let src = shared_fixture("capture_fan_ff");
    let d = tempfile::tempdir().unwrap();
    std::fs::copy(
        src.join("poses_bounds.npy"),
        d.path().join("poses_bounds.npy"),
    )
    .unwrap();
    std::os::unix::fs::symlink(src.join("images"), d.path().join("images")).unwrap();
    let colmap = Dataset::load(&src, &LoadOptions::default()).unwrap();
    let llff = Dataset::load(d.path(), &LoadOptions::default()).unwrap();
    assert_eq!(llff.layout, alphasurf::data::Layout::Llff);
    assert_eq!(llff.split_rule, SplitRule::EveryNth(8));
    let pose = crate::data_common::max_pose_difference(&colmap, &llff);
    assert!(pose < 1e-5, "max pose difference {pose:e}");
    for (sa, sb) in colmap.splits().iter().zip(llff.splits()) {
        for (fa, fb) in sa.frames.iter().zip(&sb.frames) {
            let (a, b) = (fa.camera, fb.camera);
            assert_eq!(
                (a.fx, a.fy, a.cx, a.cy, a.width, a.height),
                (b.fx, b.fy, b.cx, b.cy, b.width, b.height)
            );
            assert!(fa.image == fb.image);
        }
    }
    let fg = llff.foreground.as_ref().expect("a foreground box");
    let (lo, hi) = object_box(&src);
    assert!(fg.bounds.lo().cmple(lo).all() && fg.bounds.hi().cmpge(hi).all());
    assert!(fg.how.contains("no sparse points"), "{}", fg.how);
    // A pose count that disagrees with the images is an error naming both.
    std::fs::remove_file(d.path().join("images")).unwrap();
    std::fs::create_dir(d.path().join("images")).unwrap();
    std::fs::copy(
        src.join("images/0000.png"),
        d.path().join("images/0000.png"),
    )
    .unwrap();
    let err = format!(
        "{:#}",
        Dataset::load(d.path(), &LoadOptions::default()).unwrap_err()
    );
    assert!(
        err.contains("1 images") && err.contains("poses_bounds.npy"),
        "{err}"
    );
}

/// A damaged model is refused with the file and the entry named, not trained with a fallback:
/// an LLFF near bound of 0 (the nearest depth NDC would put its near plane at), and a COLMAP
/// sparse point at NaN (the points bound the object). Poses that are valid but all one pose load
/// with a warning.
#[test]
fn damaged_capture_models_are_refused() {
    let src = shared_fixture("capture_fan_ff");
    let load_err = |dir: &std::path::Path| {
        format!(
            "{:#}",
            Dataset::load(dir, &LoadOptions::default()).unwrap_err()
        )
    };
    // LLFF: image 3's near bound set to 0 (npy v1: a 10-byte preamble, then the header).
    let d = tempfile::tempdir().unwrap();
    let mut npy = std::fs::read(src.join("poses_bounds.npy")).unwrap();
    let data = 10 + u16::from_le_bytes([npy[8], npy[9]]) as usize;
    let at = data + (3 * 17 + 15) * 8;
    npy[at..at + 8].copy_from_slice(&0f64.to_le_bytes());
    std::fs::write(d.path().join("poses_bounds.npy"), &npy).unwrap();
    std::os::unix::fs::symlink(src.join("images"), d.path().join("images")).unwrap();
    let err = load_err(d.path());
    assert!(
        err.contains("poses_bounds.npy") && err.contains("image 3") && err.contains("near 0"),
        "{err}"
    );
    // COLMAP text: the second point's X is NaN.
    let (_d, dir) = colmap_copy(&src, |file, n, f| {
        if file == "points3D.txt" && n == 1 {
            f[1] = "nan".into();
        }
    });
    let err = load_err(&dir);
    assert!(
        err.contains("points3D.txt") && err.contains("point 2") && err.contains("NaN"),
        "{err}"
    );
    // Every image given the first one's pose: it loads (nothing in the files is invalid), and
    // `inspect` warns that the views have no parallax.
    let mut first: Option<Vec<String>> = None;
    let (_d, dir) = colmap_copy(&src, |file, _, f| {
        if file == "images.txt" && f.len() == 10 {
            let pose = first.get_or_insert_with(|| f[1..8].to_vec());
            f[1..8].clone_from_slice(pose);
        }
    });
    let ds = Dataset::load(&dir, &LoadOptions::default()).unwrap();
    let warnings = inspect(&ds).warnings;
    assert!(
        warnings.iter().any(|w| w.contains("no parallax")),
        "{warnings:?}"
    );
    let ok = Dataset::load(&src, &LoadOptions::default()).unwrap();
    assert!(!inspect(&ok).warnings.iter().any(|w| w.contains("parallax")));
}

/// A copy of `src`'s COLMAP text model with `edit(file, n, fields)` applied to the fields of each
/// data line (n: its index among the file's data lines), and a link to its images.
fn colmap_copy(
    src: &std::path::Path,
    mut edit: impl FnMut(&str, usize, &mut Vec<String>),
) -> (tempfile::TempDir, std::path::PathBuf) {
    let d = tempfile::tempdir().unwrap();
    let sparse = d.path().join("sparse/0");
    std::fs::create_dir_all(&sparse).unwrap();
    for file in ["cameras.txt", "images.txt", "points3D.txt"] {
        let text = std::fs::read_to_string(src.join("sparse/0").join(file)).unwrap();
        let mut n = 0;
        let lines: Vec<String> = text
            .lines()
            .map(|l| {
                if l.starts_with('#') || l.trim().is_empty() {
                    return l.to_string();
                }
                let mut f: Vec<String> = l.split_whitespace().map(String::from).collect();
                edit(file, n, &mut f);
                n += 1;
                f.join(" ")
            })
            .collect();
        std::fs::write(sparse.join(file), lines.join("\n")).unwrap();
    }
    std::os::unix::fs::symlink(src.join("images"), d.path().join("images")).unwrap();
    let dir = d.path().to_path_buf();
    (d, dir)
}

/// `--space auto` gives the forward-facing fan NDC (its cameras look within 45° of their mean
/// direction; the near plane from its sparse points) and the 360° birdcage its box; the object
/// lies inside the NDC cube and every corner of it maps back; the rays the sampler draws on the
/// device's formula are the host's NDC rays of the same pixels.
#[test]
fn forward_facing_capture_trains_in_ndc() {
    let auto = LoadOptions {
        space: Space::Auto,
        ..Default::default()
    };
    let orbit = Dataset::load(&shared_fixture("capture_birdcage"), &auto).unwrap();
    assert!(orbit.scene.ndc.is_none(), "{}", orbit.space);
    assert!(
        orbit.space.contains("not forward-facing"),
        "{}",
        orbit.space
    );
    // Without alpha in a box, `auto` puts the room on background spheres: no advice then. On a
    // white background the orbit gets the advice to use them, or to train in the room's box.
    assert_eq!(orbit.background, BackgroundMode::Spheres);
    let advice = |ds: &Dataset| {
        inspect(ds)
            .warnings
            .into_iter()
            .find(|w| w.contains("train in the room: --box="))
    };
    assert!(advice(&orbit).is_none());
    let white = LoadOptions {
        background: BackgroundMode::White,
        ..auto
    };
    let orbit_white = Dataset::load(&shared_fixture("capture_birdcage"), &white).unwrap();
    let room = advice(&orbit_white).expect("the room advice for the 360° capture on white");
    assert!(room.contains("--background spheres"), "{room}");
    let bounds: Vec<f32> = room
        .rsplit("--box=")
        .next()
        .unwrap()
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    let (lo, hi) = object_box(&shared_fixture("capture_birdcage"));
    assert!(
        (0..3).all(|a| bounds[a] <= lo[a] && bounds[3 + a] >= hi[a]),
        "the room {bounds:?} does not hold the object {lo}..{hi}"
    );

    let dir = shared_fixture("capture_fan_ff");
    let ff = Dataset::load(&dir, &auto).unwrap();
    let ndc = ff
        .scene
        .ndc
        .unwrap_or_else(|| panic!("no NDC: {}", ff.space));
    assert!(ff.space.starts_with("NDC"), "{}", ff.space);
    assert!(advice(&ff).is_none());
    assert_eq!(
        ff.background,
        BackgroundMode::White,
        "NDC reaches infinite depth"
    );
    let (lo, hi) = object_box(&dir);
    for i in 0..8 {
        let c = Vec3::select(glam::BVec3::new(i & 1 != 0, i & 2 != 0, i & 4 != 0), hi, lo);
        let q = ndc.to_ndc(c.to_array()).unwrap();
        assert!(q.iter().all(|v| v.abs() < 1.0), "corner {c} → NDC {q:?}");
        let back = Vec3::from_array(ndc.to_world(q));
        assert!(
            (back - c).abs().max_element() < 1e-4,
            "{c} → {q:?} → {back}"
        );
    }

    let views = TrainViews::new(&ff.train, &ff.scene).unwrap();
    let drawn = sample_rays(views.set(), 11, 2048).unwrap();
    let bits = views.set().key_bits();
    for (i, &k) in drawn.keys.iter().enumerate() {
        let (v, x, y) = key_pixel(k, bits);
        let (o, d) = ff.train.frames[v as usize].camera.pixel_ray(x, y);
        let want = ff.scene.ray(o, d);
        for (c, (&got, w)) in drawn.rays[6 * i..6 * i + 6].iter().zip(want).enumerate() {
            assert!(
                (got - w).abs() <= 1e-5 * w.abs().max(1.0),
                "ray {i} ({v}, {x}, {y}) component {c}: sampler {got}, host {w}"
            );
        }
    }
}
