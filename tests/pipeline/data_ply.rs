//! PLY point clouds: round trip with extras, the fixture's 1 M points, ascii input, and clean
//! errors naming the file for unreadable, empty and malformed files.

use crate::data_common;

use alphasurf::io::{
    read_ply, read_points, write_ply, write_points, Extra, ExtraValues, PointCloud,
};
use std::path::Path;

fn err(path: &Path) -> String {
    format!("{:#}", read_ply(path).expect_err("should fail"))
}

#[test]
fn round_trip_with_extras() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("c.ply");
    let cloud = PointCloud {
        points: vec![[0.0, 1.0, -2.5], [1e-7, 3.25, 1e6], [-0.0, 0.5, 0.125]],
        extras: vec![
            Extra {
                name: "alpha".into(),
                values: ExtraValues::Float(vec![0.1, 0.5, 1.0]),
            },
            Extra {
                name: "red".into(),
                values: ExtraValues::UChar(vec![0, 128, 255]),
            },
        ],
    };
    write_ply(&p, &cloud).unwrap();
    let text = std::fs::read(&p).unwrap();
    let header = String::from_utf8_lossy(
        &text[..text.windows(10).position(|w| w == b"end_header").unwrap()],
    )
    .to_string();
    assert!(
        header.contains("format binary_little_endian 1.0") && header.contains("element vertex 3"),
        "{header}"
    );
    assert!(
        header.contains("property float x") && header.contains("property uchar red"),
        "{header}"
    );
    assert_eq!(read_ply(&p).unwrap(), cloud);
    assert_eq!(
        text.len(),
        header.len() + "end_header\n".len() + 3 * (16 + 1)
    );
    write_points(&p, &cloud.points).unwrap();
    assert_eq!(read_points(&p).unwrap(), cloud.points);
}

#[test]
fn reads_the_fixture_points() {
    let pts = read_points(&data_common::fixture().join("gt_points.ply")).unwrap();
    assert_eq!(pts.len(), 1_000_000);
    assert!(pts
        .iter()
        .all(|p| p.iter().all(|v| v.is_finite() && v.abs() < 1.5)));
}

#[test]
fn reads_ascii_and_double_and_skips_leading_elements() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("a.ply");
    std::fs::write(
        &p,
        "ply\nformat ascii 1.0\nelement camera 1\nproperty float f\nelement vertex 2\nproperty double x\nproperty double y\nproperty double z\nproperty uchar q\nend_header\n7\n1 2 3 4\n-1 -2 -3.5 200\n",
    )
    .unwrap();
    let c = read_ply(&p).unwrap();
    assert_eq!(c.points, vec![[1.0, 2.0, 3.0], [-1.0, -2.0, -3.5]]);
    assert_eq!(c.extras[0].values, ExtraValues::UChar(vec![4, 200]));
}

#[test]
fn other_vertex_properties_are_skipped() {
    // Issue 24: a PLY with int, double and list properties beside x, y, z was rejected although
    // eval needs only the positions.
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("mixed.ply");
    std::fs::write(
        &p,
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty int label\nproperty float y\nproperty double q\nproperty float z\nproperty list uchar int idx\nproperty float w\nproperty uchar c\nend_header\n1 7 2 0.5 3 2 4 5 0.25 9\n-1 8 -2 1.5 -3 0 0.75 10\n",
    )
    .unwrap();
    let c = read_ply(&p).unwrap();
    assert_eq!(c.points, vec![[1.0, 2.0, 3.0], [-1.0, -2.0, -3.0]]);
    let names: Vec<&str> = c.extras.iter().map(|e| e.name.as_str()).collect();
    assert_eq!(names, ["w", "c"]);
    assert_eq!(c.extras[0].values, ExtraValues::Float(vec![0.25, 0.75]));
    assert_eq!(c.extras[1].values, ExtraValues::UChar(vec![9, 10]));
}

#[test]
fn rejects_bad_files_with_the_file_name() {
    let d = tempfile::tempdir().unwrap();
    let path = |n: &str| d.path().join(n);
    let msg = err(&path("missing.ply"));
    assert!(
        msg.contains("missing.ply") && msg.contains("cannot open"),
        "{msg}"
    );

    std::fs::write(path("empty_file.ply"), b"").unwrap();
    let msg = err(&path("empty_file.ply"));
    assert!(
        msg.contains("empty_file.ply") && msg.contains("header"),
        "{msg}"
    );

    std::fs::write(path("garbage.ply"), b"hello world\n\x00\x01").unwrap();
    let msg = err(&path("garbage.ply"));
    assert!(
        msg.contains("garbage.ply") && msg.contains("header"),
        "{msg}"
    );

    let hdr = |n: usize, props: &str| {
        format!("ply\nformat binary_little_endian 1.0\nelement vertex {n}\n{props}end_header\n")
    };
    let xyz = "property float x\nproperty float y\nproperty float z\n";
    std::fs::write(path("zero.ply"), hdr(0, xyz)).unwrap();
    let msg = err(&path("zero.ply"));
    assert!(msg.contains("zero.ply") && msg.contains("empty"), "{msg}");

    let mut trunc = hdr(3, xyz).into_bytes();
    trunc.extend_from_slice(&[0u8; 20]); // 3 points need 36 bytes
    std::fs::write(path("truncated.ply"), trunc).unwrap();
    let msg = err(&path("truncated.ply"));
    assert!(
        msg.contains("truncated.ply") && msg.contains("truncated"),
        "{msg}"
    );

    std::fs::write(path("huge.ply"), hdr(4_000_000_000, xyz)).unwrap();
    let msg = err(&path("huge.ply"));
    assert!(
        msg.contains("huge.ply") && msg.contains("truncated"),
        "{msg}"
    );

    std::fs::write(
        path("noz.ply"),
        hdr(1, "property float x\nproperty float y\n"),
    )
    .unwrap();
    let msg = err(&path("noz.ply"));
    assert!(msg.contains("noz.ply") && msg.contains("'z'"), "{msg}");

    let mut nan = hdr(1, xyz).into_bytes();
    for v in [1.0f32, f32::NAN, 0.0] {
        nan.extend_from_slice(&v.to_le_bytes());
    }
    std::fs::write(path("nan.ply"), nan).unwrap();
    let msg = err(&path("nan.ply"));
    assert!(
        msg.contains("nan.ply") && msg.contains("non-finite"),
        "{msg}"
    );

    // x/y/z must be float or double.
    std::fs::write(
        path("intxyz.ply"),
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty int x\nproperty float y\nproperty float z\nend_header\n1 2 3\n",
    )
    .unwrap();
    let msg = err(&path("intxyz.ply"));
    assert!(
        msg.contains("intxyz.ply") && msg.contains("unsupported"),
        "{msg}"
    );

    std::fs::write(path("noverts.ply"), "ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n").unwrap();
    let msg = err(&path("noverts.ply"));
    assert!(
        msg.contains("noverts.ply") && msg.contains("'vertex'"),
        "{msg}"
    );
}
