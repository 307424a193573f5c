//! PLY point clouds: the `vertex` element's x, y, z (float or double) plus optional extra scalar
//! float/uchar properties. Writing is always binary little-endian with float xyz.
//!
//! Reading uses `ply-rs-bw` (header grammar, ascii/binary payloads, bounded preallocation) with a
//! custom row type, so no per-point maps are built. Vertex properties other than x, y, z and
//! float/uchar extras (ints, doubles, lists) are read past and dropped. Files that cannot be
//! read, have no vertices, lack x/y/z (float or double), end early or hold non-finite coordinates
//! are rejected with an error naming the file.

use anyhow::{bail, Context};
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{
    Addable, ElementDef, Encoding, Header, PropertyAccess, PropertyAccessResult, PropertyDef,
    PropertyType, ScalarType,
};
use std::io::{BufReader, Write};
use std::path::Path;

/// Values of one extra per-vertex property.
#[derive(Clone, Debug, PartialEq)]
pub enum ExtraValues {
    /// `property float NAME`.
    Float(Vec<f32>),
    /// `property uchar NAME`.
    UChar(Vec<u8>),
}

impl ExtraValues {
    fn len(&self) -> usize {
        match self {
            ExtraValues::Float(v) => v.len(),
            ExtraValues::UChar(v) => v.len(),
        }
    }
}

/// A named extra per-vertex property.
#[derive(Clone, Debug, PartialEq)]
pub struct Extra {
    /// Property name.
    pub name: String,
    /// One value per point.
    pub values: ExtraValues,
}

/// Points with optional extra per-point properties.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointCloud {
    /// Positions.
    pub points: Vec<[f32; 3]>,
    /// Extra properties, each as long as `points`.
    pub extras: Vec<Extra>,
}

impl PointCloud {
    /// Keep the points (and their extras) for which `keep` holds.
    pub fn retain(&mut self, keep: impl Fn(&[f32; 3]) -> bool) {
        let mask: Vec<bool> = self.points.iter().map(keep).collect();
        let pick = |i: &usize| mask[*i];
        self.points = (0..mask.len())
            .filter(pick)
            .map(|i| self.points[i])
            .collect();
        for e in &mut self.extras {
            e.values = match &e.values {
                ExtraValues::Float(v) => {
                    ExtraValues::Float((0..mask.len()).filter(pick).map(|i| v[i]).collect())
                }
                ExtraValues::UChar(v) => {
                    ExtraValues::UChar((0..mask.len()).filter(pick).map(|i| v[i]).collect())
                }
            };
        }
    }
}

/// One vertex as read: xyz and the extras in header order.
struct Row {
    xyz: [f32; 3],
    extras: Vec<f32>,
}

impl Row {
    fn set(&mut self, name: &str, v: f32) -> PropertyAccessResult {
        match name {
            "x" => self.xyz[0] = v,
            "y" => self.xyz[1] = v,
            "z" => self.xyz[2] = v,
            _ => self.extras.push(v),
        }
        PropertyAccessResult::Set
    }
}

impl PropertyAccess for Row {
    fn new() -> Self {
        Row {
            xyz: [0.0; 3],
            extras: Vec::new(),
        }
    }
    fn set_float(&mut self, name: &str, v: f32) -> PropertyAccessResult {
        self.set(name, v)
    }
    fn set_double(&mut self, name: &str, v: f64) -> PropertyAccessResult {
        // Double extras are skipped (see `read_inner`); only x, y, z may be double.
        match name {
            "x" | "y" | "z" => self.set(name, v as f32),
            _ => PropertyAccessResult::Ignored,
        }
    }
    fn set_uchar(&mut self, name: &str, v: u8) -> PropertyAccessResult {
        self.set(name, v as f32)
    }
}

/// Reads the `vertex` element of a PLY file.
pub fn read_ply(path: &Path) -> anyhow::Result<PointCloud> {
    read_inner(path).with_context(|| format!("reading PLY {}", path.display()))
}

/// Reads only the positions of a PLY file.
pub fn read_points(path: &Path) -> anyhow::Result<Vec<[f32; 3]>> {
    Ok(read_ply(path)?.points)
}

fn read_inner(path: &Path) -> anyhow::Result<PointCloud> {
    let name = path.display();
    let f = std::fs::File::open(path).with_context(|| format!("{name}: cannot open"))?;
    let mut reader = Reader::new(BufReader::new(f));
    let parser = Parser::<Row>::new();
    let header = parser
        .read_header(&mut reader)
        .map_err(|e| anyhow::anyhow!("{name}: not a valid PLY header: {e}"))?;
    let Some(vdef) = header.elements.get("vertex") else {
        bail!("{name}: no 'vertex' element");
    };
    if vdef.count == 0 {
        bail!("{name}: empty point cloud (0 vertices)");
    }
    let mut extra_defs = Vec::new();
    for (pname, p) in vdef.properties.iter() {
        let xyz = matches!(pname.as_str(), "x" | "y" | "z");
        match (&p.data_type, xyz) {
            (PropertyType::Scalar(ScalarType::Float | ScalarType::Double), true) => {}
            (PropertyType::Scalar(ScalarType::Float), false) => extra_defs.push((pname.clone(), false)),
            (PropertyType::Scalar(ScalarType::UChar), false) => extra_defs.push((pname.clone(), true)),
            (t, true) => bail!("{name}: vertex property '{pname}' has unsupported type {t:?} (x/y/z: float or double)"),
            // Other properties (ints, doubles, lists) are not needed here: skipped.
            (_, false) => {}
        }
    }
    for axis in ["x", "y", "z"] {
        if !vdef.properties.contains_key(axis) {
            bail!("{name}: vertex element has no '{axis}' property");
        }
    }
    // Elements before `vertex` must be read (and dropped) to reach it.
    let mut rows = Vec::new();
    for (ename, edef) in header.elements.iter() {
        let r = parser
            .read_payload_for_element(&mut reader, edef, &header)
            .map_err(|e| anyhow::anyhow!("{name}: malformed or truncated '{ename}' data: {e}"))?;
        if ename == "vertex" {
            rows = r;
            break;
        }
    }
    if rows.len() != vdef.count {
        bail!(
            "{name}: header declares {} vertices but {} were read",
            vdef.count,
            rows.len()
        );
    }
    let mut extras: Vec<Extra> = extra_defs
        .iter()
        .map(|(n, uchar)| Extra {
            name: n.clone(),
            values: if *uchar {
                ExtraValues::UChar(Vec::with_capacity(rows.len()))
            } else {
                ExtraValues::Float(Vec::with_capacity(rows.len()))
            },
        })
        .collect();
    let mut points = Vec::with_capacity(rows.len());
    for (i, r) in rows.into_iter().enumerate() {
        if !r.xyz.iter().all(|v| v.is_finite()) {
            bail!("{name}: vertex {i} has a non-finite coordinate {:?}", r.xyz);
        }
        points.push(r.xyz);
        for (e, v) in extras.iter_mut().zip(r.extras) {
            match &mut e.values {
                ExtraValues::Float(a) => a.push(v),
                ExtraValues::UChar(a) => a.push(v as u8),
            }
        }
    }
    Ok(PointCloud { points, extras })
}

/// Writes a binary little-endian PLY with float x, y, z and the extras, atomically.
pub fn write_ply(path: &Path, cloud: &PointCloud) -> anyhow::Result<()> {
    let name = path.display();
    for e in &cloud.extras {
        if e.values.len() != cloud.points.len() {
            bail!(
                "{name}: extra '{}' has {} values for {} points",
                e.name,
                e.values.len(),
                cloud.points.len()
            );
        }
    }
    let mut header = Header::new();
    header.encoding = Encoding::BinaryLittleEndian;
    header.comments.push("written by alphasurf".into());
    let mut el = ElementDef::new("vertex".into());
    el.count = cloud.points.len();
    for axis in ["x", "y", "z"] {
        el.properties.add(PropertyDef::new(
            axis.into(),
            PropertyType::Scalar(ScalarType::Float),
        ));
    }
    for e in &cloud.extras {
        let t = match e.values {
            ExtraValues::Float(_) => ScalarType::Float,
            ExtraValues::UChar(_) => ScalarType::UChar,
        };
        el.properties
            .add(PropertyDef::new(e.name.clone(), PropertyType::Scalar(t)));
    }
    header.elements.add(el);
    super::atomic::write_atomic(path, |w| {
        ply_rs_bw::writer::Writer::<Row>::new()
            .write_header(w, &header)
            .with_context(|| format!("{name}: writing header"))?;
        let mut buf = Vec::with_capacity(64);
        for (i, p) in cloud.points.iter().enumerate() {
            buf.clear();
            for v in p {
                buf.extend_from_slice(&v.to_le_bytes());
            }
            for e in &cloud.extras {
                match &e.values {
                    ExtraValues::Float(a) => buf.extend_from_slice(&a[i].to_le_bytes()),
                    ExtraValues::UChar(a) => buf.push(a[i]),
                }
            }
            w.write_all(&buf)
                .with_context(|| format!("{name}: write failed"))?;
        }
        Ok(())
    })
}

/// Writes positions only.
pub fn write_points(path: &Path, points: &[[f32; 3]]) -> anyhow::Result<()> {
    write_ply(
        path,
        &PointCloud {
            points: points.to_vec(),
            extras: Vec::new(),
        },
    )
}
