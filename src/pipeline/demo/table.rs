//! The demo's tables as text: the results (method | Chamfer ×10⁻² | F1 | test PSNR | wall time)
//! and each object group's share of the Chamfer distance, aligned or as markdown.

use super::Row;

/// Text of a table cell for an optional number.
fn cell(v: Option<f64>, prec: usize, unit: &str) -> String {
    match v {
        Some(x) if x.is_finite() => format!("{x:.prec$}{unit}"),
        _ => "—".into(),
    }
}

/// The results table as plain text (`markdown`: as a markdown table).
pub fn table(rows: &[Row], markdown: bool) -> String {
    let head = ["method", "Chamfer ×10⁻²", "F1", "test PSNR", "wall time"];
    let body: Vec<Vec<String>> = rows
        .iter()
        .map(|r| {
            vec![
                r.method.clone(),
                cell(r.chamfer_e2, 4, ""),
                cell(r.f1, 4, ""),
                cell(r.test_psnr, 2, " dB"),
                if r.error.is_some() {
                    "failed".into()
                } else {
                    cell(Some(r.wall_s), 1, " s")
                },
            ]
        })
        .collect();
    layout(&head, &body, markdown)
}

/// Where the Chamfer distance comes from: each object group's share of it (`eval`'s split over
/// the scene's objects) for the best Plenoxels level and for αSurf, largest Plenoxels share
/// first. None unless both rows have the split.
pub fn objects_table(best: &Row, surf: &Row, markdown: bool) -> Option<String> {
    let (b, a) = (
        &best.metrics.as_ref()?.objects,
        &surf.metrics.as_ref()?.objects,
    );
    if b.is_empty() || b.len() != a.len() {
        return None;
    }
    let mut pairs: Vec<_> = b.iter().zip(a).filter(|(b, a)| b.name == a.name).collect();
    pairs.sort_by(|x, y| y.0.chamfer_share.total_cmp(&x.0.chamfer_share));
    let head = [
        "object group",
        "GT points",
        "best Plen share",
        "αSurf share",
        "change",
    ];
    let body: Vec<Vec<String>> = pairs
        .iter()
        .map(|(b, a)| {
            let change = 100.0 * (a.chamfer_share - b.chamfer_share) / b.chamfer_share;
            vec![
                b.name.clone(),
                b.n_gt.to_string(),
                cell(Some(100.0 * b.chamfer_share), 4, ""),
                cell(Some(100.0 * a.chamfer_share), 4, ""),
                if change.is_finite() {
                    format!("{change:+.1} %")
                } else {
                    "—".into()
                },
            ]
        })
        .collect();
    Some(layout(&head, &body, markdown))
}

/// A table with a left-aligned first column and right-aligned others, as aligned plain text or
/// (`markdown`) a markdown table.
fn layout(head: &[&str], body: &[Vec<String>], markdown: bool) -> String {
    let mut s = String::new();
    if markdown {
        s += &format!(
            "| {} |\n|---{}|\n",
            head.join(" | "),
            "|---:".repeat(head.len() - 1)
        );
        for r in body {
            s += &format!("| {} |\n", r.join(" | "));
        }
        return s;
    }
    let w: Vec<usize> = (0..head.len())
        .map(|i| {
            body.iter()
                .map(|r| r[i].chars().count())
                .chain([head[i].chars().count()])
                .max()
                .unwrap_or(0)
        })
        .collect();
    let line = |c: Vec<&str>| {
        let mut l = format!("{:<w0$}", c[0], w0 = w[0]);
        for i in 1..c.len() {
            let pad = w[i] - c[i].chars().count();
            l += &format!("  {}{}", " ".repeat(pad), c[i]);
        }
        l + "\n"
    };
    s += &line(head.to_vec());
    for r in body {
        s += &line(r.iter().map(String::as_str).collect());
    }
    s
}

#[cfg(test)]
mod tests {
    use super::super::tests::row;
    use super::*;

    #[test]
    fn tables_align_and_show_failures() {
        let mut failed = row("αSurf", "alphasurf", None, None);
        failed.error = Some("boom".into());
        let rows = vec![
            row("Plen σ = 10", "plenoxels", Some(10.0), Some(0.91234)),
            failed,
        ];
        let t = table(&rows, false);
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines.len(), 3);
        let w = lines[0].chars().count();
        assert!(lines.iter().all(|l| l.chars().count() == w), "{t}");
        assert!(lines[1].contains("0.9123") && lines[1].contains("25.00 dB"));
        assert!(lines[2].contains("failed") && lines[2].contains('—'));
        let md = table(&rows, true);
        assert!(md.starts_with("| method | Chamfer ×10⁻² |"));
        assert_eq!(md.lines().count(), 4);
    }

    #[test]
    fn object_table_compares_shares_largest_plenoxels_share_first() {
        use crate::eval::metrics::from_distances;
        use crate::eval::objects::GroupError;
        let with = |shares: [f64; 2]| {
            let mut r = row("x", "plenoxels", None, Some(1.0));
            let mut m = from_distances(&[0.1], &[0.2], &Default::default());
            m.objects = ["wire", "pot"]
                .iter()
                .zip(shares)
                .map(|(n, s)| GroupError {
                    name: n.to_string(),
                    n_gt: 7,
                    n_pred: 3,
                    mean_d2s: 0.1,
                    mean_s2d: 0.2,
                    chamfer_share: s,
                })
                .collect();
            r.metrics = Some(m);
            r
        };
        let (b, a) = (with([0.001, 0.004]), with([0.0005, 0.005]));
        let t = objects_table(&b, &a, false).unwrap();
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines.len(), 3, "{t}");
        assert!(
            lines[1].starts_with("pot") && lines[1].ends_with("+25.0 %"),
            "{t}"
        );
        assert!(
            lines[2].starts_with("wire") && lines[2].ends_with("-50.0 %"),
            "{t}"
        );
        assert!(
            lines[2].contains("0.1000") && lines[2].contains("0.0500"),
            "{t}"
        );
        let w = lines[0].chars().count();
        assert!(lines.iter().all(|l| l.chars().count() == w), "{t}");
        assert_eq!(objects_table(&b, &a, true).unwrap().lines().count(), 4);
        let mut bare = with([0.0; 2]);
        bare.metrics.as_mut().unwrap().objects.clear();
        assert!(objects_table(&bare, &a, false).is_none());
        assert!(objects_table(&row("y", "alphasurf", None, None), &a, false).is_none());
    }
}
