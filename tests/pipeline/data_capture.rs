//! Captures as they arrive (`../shared/fixtures/capture_*`: an object in a room, COLMAP text
//! model, no masks, no split file): the foreground box found from the cameras and sparse points,
//! and the split stated.

use crate::data_common::shared_fixture;
use alphasurf::data::{Dataset, LoadOptions, SplitRule};
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
    }
}
