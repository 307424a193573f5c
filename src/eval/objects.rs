//! Where a Chamfer distance comes from, object by object. A scene written by `make-scene` (and the
//! fixtures' generator) lists in its `scene.json` each object's range of ground-truth points
//! (`point_start`, `point_count` into `gt_points.ply`). Objects are grouped by name with a trailing
//! `_<number>` removed (`wire_0` … `wire_8` → `wire`). Each GT point counts toward its group's s2d;
//! each predicted point toward the group of its nearest GT point. A group's share of the Chamfer
//! distance is ½(Σ its d2s / #d2s used + Σ its s2d / #s2d used) over the distances < max_dist, so
//! the shares add up to the Chamfer distance.

use anyhow::{bail, ensure, Context, Result};
use std::path::Path;

/// Group name of an object: its name without a trailing `_<digits>`.
pub fn group_name(name: &str) -> &str {
    match name.rsplit_once('_') {
        Some((head, tail))
            if !head.is_empty() && !tail.is_empty() && tail.bytes().all(|b| b.is_ascii_digit()) =>
        {
            head
        }
        _ => name,
    }
}

/// The object groups of a ground-truth cloud: group names (in order of first appearance) and the
/// group of every GT point (as read, before any thinning).
#[derive(Clone, Debug, PartialEq)]
pub struct GtGroups {
    pub names: Vec<String>,
    pub of_point: Vec<u32>,
}

/// Read the objects' GT point ranges from a `scene.json` for a cloud of `n_gt` points. The ranges
/// must tile 0..n_gt without gaps or overlaps (in any order).
pub fn load_groups(scene_json: &Path, n_gt: usize) -> Result<GtGroups> {
    let name = scene_json.display();
    let text = std::fs::read_to_string(scene_json).with_context(|| format!("reading {name}"))?;
    let v: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("{name}: not valid JSON"))?;
    let objects = v
        .get("objects")
        .and_then(|o| o.as_array())
        .with_context(|| format!("{name}: no \"objects\" list"))?;
    let mut ranges = Vec::with_capacity(objects.len());
    for (i, o) in objects.iter().enumerate() {
        let field = |k: &str| {
            o.get(k)
                .and_then(|x| x.as_u64())
                .with_context(|| format!("{name}: objects[{i}] has no integer \"{k}\""))
        };
        let label = o
            .get("name")
            .and_then(|x| x.as_str())
            .with_context(|| format!("{name}: objects[{i}] has no \"name\""))?;
        let (start, count) = (
            field("point_start")? as usize,
            field("point_count")? as usize,
        );
        ranges.push((start, count, group_name(label).to_string()));
    }
    ranges.sort_by_key(|r| r.0);
    let mut names: Vec<String> = Vec::new();
    let mut of_point = Vec::with_capacity(n_gt);
    for (start, count, group) in ranges {
        if start != of_point.len() {
            bail!(
                "{name}: object ranges leave GT points {}..{start} unassigned or overlap at \
                 {start} (the ranges must tile the cloud)",
                of_point.len()
            );
        }
        let g = match names.iter().position(|n| *n == group) {
            Some(g) => g,
            None => {
                names.push(group);
                names.len() - 1
            }
        };
        of_point.resize(start + count, g as u32);
    }
    ensure!(
        of_point.len() == n_gt,
        "{name}: the objects cover {} GT points, the cloud has {n_gt} (is it this scene's \
         gt_points.ply?)",
        of_point.len()
    );
    Ok(GtGroups { names, of_point })
}

/// One group's part of the Chamfer distance.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct GroupError {
    pub name: String,
    /// GT points of the group (after thinning).
    pub n_gt: usize,
    /// Predicted points whose nearest GT point is in the group.
    pub n_pred: usize,
    /// Mean d2s of those predicted points and mean s2d of the group's GT points, over the
    /// distances < max_dist (NaN when there are none).
    pub mean_d2s: f64,
    pub mean_s2d: f64,
    /// The group's share of the Chamfer distance (the shares add up to it).
    pub chamfer_share: f64,
}

/// Per-group errors. `gt_group[j]`: group of (thinned) GT point j; `d2s[i]`, `nearest_gt[i]`:
/// distance of predicted point i to its nearest GT point and that point's index; `s2d[j]`:
/// distance of GT point j to the prediction.
pub fn group_errors(
    names: &[String],
    gt_group: &[u32],
    d2s: &[f64],
    nearest_gt: &[usize],
    s2d: &[f64],
    max_dist: f64,
) -> Vec<GroupError> {
    #[derive(Clone, Default)]
    struct Acc {
        n_gt: usize,
        n_pred: usize,
        d2s: (f64, usize),
        s2d: (f64, usize),
    }
    let mut acc = vec![Acc::default(); names.len()];
    let (mut d2s_used, mut s2d_used) = (0usize, 0usize);
    for (&d, &j) in d2s.iter().zip(nearest_gt) {
        let a = &mut acc[gt_group[j] as usize];
        a.n_pred += 1;
        if d < max_dist {
            a.d2s.0 += d;
            a.d2s.1 += 1;
            d2s_used += 1;
        }
    }
    for (&d, &g) in s2d.iter().zip(gt_group) {
        if d.is_nan() {
            continue; // left out of completeness (`metrics::evaluate_indexed`'s `seen`)
        }
        let a = &mut acc[g as usize];
        a.n_gt += 1;
        if d < max_dist {
            a.s2d.0 += d;
            a.s2d.1 += 1;
            s2d_used += 1;
        }
    }
    let mean = |(sum, n): (f64, usize)| if n == 0 { f64::NAN } else { sum / n as f64 };
    let share = |sum: f64, used: usize| if used == 0 { 0.0 } else { sum / used as f64 };
    names
        .iter()
        .zip(acc)
        .map(|(name, a)| GroupError {
            name: name.clone(),
            n_gt: a.n_gt,
            n_pred: a.n_pred,
            mean_d2s: mean(a.d2s),
            mean_s2d: mean(a.s2d),
            chamfer_share: 0.5 * (share(a.d2s.0, d2s_used) + share(a.s2d.0, s2d_used)),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn group_names_drop_a_numeric_suffix_only() {
        assert_eq!(group_name("wire_12"), "wire");
        assert_eq!(group_name("frame_bottom"), "frame_bottom");
        assert_eq!(group_name("leaf_"), "leaf_");
        assert_eq!(group_name("_7"), "_7");
        assert_eq!(group_name("pot"), "pot");
        assert_eq!(group_name("a_b_3"), "a_b");
    }

    #[test]
    fn shares_add_up_to_the_chamfer_distance() {
        let names = vec!["a".to_string(), "b".to_string()];
        let gt_group = [0, 0, 1];
        let d2s = [0.1, 0.3, 2.0, 0.5];
        let nearest = [0, 2, 2, 1];
        let s2d = [0.2, 0.4, 0.6];
        let e = group_errors(&names, &gt_group, &d2s, &nearest, &s2d, 1.5);
        // d2s used: 0.1, 0.3, 0.5 (2.0 ≥ 1.5): mean 0.3; s2d mean 0.4; Chamfer 0.35.
        assert_eq!((e[0].n_pred, e[1].n_pred), (2, 2));
        assert_eq!((e[0].n_gt, e[1].n_gt), (2, 1));
        assert!((e[0].mean_d2s - 0.3).abs() < 1e-15 && (e[1].mean_d2s - 0.3).abs() < 1e-15);
        assert!((e[0].mean_s2d - 0.3).abs() < 1e-15 && (e[1].mean_s2d - 0.6).abs() < 1e-15);
        assert!((e[0].chamfer_share - 0.5 * (0.6 / 3.0 + 0.6 / 3.0)).abs() < 1e-15);
        assert!((e[1].chamfer_share - 0.5 * (0.3 / 3.0 + 0.6 / 3.0)).abs() < 1e-15);
        assert!((e[0].chamfer_share + e[1].chamfer_share - 0.35).abs() < 1e-15);
    }

    fn scene(objects: &str) -> (tempfile::TempDir, std::path::PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("scene.json");
        std::fs::write(&p, format!("{{\"objects\": {objects}}}")).unwrap();
        (dir, p)
    }

    #[test]
    fn groups_tile_the_cloud_in_any_order() {
        let (_d, p) = scene(
            r#"[{"name": "wire_1", "point_start": 3, "point_count": 2},
                {"name": "pot", "point_start": 0, "point_count": 2},
                {"name": "wire_0", "point_start": 2, "point_count": 1}]"#,
        );
        let g = load_groups(&p, 5).unwrap();
        assert_eq!(g.names, ["pot", "wire"]);
        assert_eq!(g.of_point, [0, 0, 1, 1, 1]);
    }

    #[test]
    fn bad_scene_files_are_errors_naming_the_file() {
        for (objects, n, want) in [
            (
                r#"[{"name": "a", "point_start": 0, "point_count": 2}]"#,
                3,
                "cover 2 GT points",
            ),
            (
                r#"[{"name": "a", "point_start": 0, "point_count": 2},
                    {"name": "b", "point_start": 1, "point_count": 2}]"#,
                3,
                "overlap at 1",
            ),
            (
                r#"[{"name": "a", "point_start": 1, "point_count": 2}]"#,
                3,
                "0..1 unassigned",
            ),
            (
                r#"[{"name": "a", "point_count": 2}]"#,
                2,
                "no integer \"point_start\"",
            ),
            (
                r#"[{"point_start": 0, "point_count": 2}]"#,
                2,
                "no \"name\"",
            ),
            ("3", 2, "no \"objects\" list"),
        ] {
            let (_d, p) = scene(objects);
            let e = format!("{:#}", load_groups(&p, n).unwrap_err());
            assert!(
                e.contains("scene.json") && e.contains(want),
                "{objects}: {e}"
            );
        }
        let (_d, p) = scene("[");
        let e = format!("{:#}", load_groups(&p, 1).unwrap_err());
        assert!(e.contains("not valid JSON"), "{e}");
    }
}
