//! Meshes as binary little-endian PLY: `vertex` (float x, y, z, nx, ny, nz, level, alpha, and
//! uchar red, green, blue for a coloured mesh) and
//! `face` (`list uchar int vertex_indices`, the form Blender and MeshLab read), written atomically.
//! Reading takes the positions and faces of any PLY mesh (ascii or binary, through `ply-rs-bw`;
//! polygons are split into triangle fans) and rejects indices out of range or non-finite
//! positions, naming the file.

use super::Mesh;
use anyhow::{bail, ensure, Context, Result};
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{PropertyAccess, PropertyAccessResult};
use std::io::{BufReader, Write};
use std::path::Path;

/// Write `mesh` (Blender units) to `path` atomically.
pub fn write_mesh_ply(path: &Path, mesh: &Mesh) -> Result<()> {
    let name = path.display();
    let n = mesh.positions.len();
    let coloured = !mesh.colour.is_empty();
    ensure!(
        mesh.normals.len() == n
            && mesh.level.len() == n
            && mesh.alpha.len() == n
            && (!coloured || mesh.colour.len() == n),
        "{name}: per-vertex attributes do not match the {n} vertices"
    );
    ensure!(
        n <= i32::MAX as usize,
        "{name}: {n} vertices, more than a PLY int index can name"
    );
    ensure!(
        mesh.positions
            .iter()
            .chain(&mesh.normals)
            .flatten()
            .chain(&mesh.level)
            .chain(&mesh.alpha)
            .all(|v| v.is_finite()),
        "{name}: the mesh has a non-finite position, normal, level or alpha"
    );
    ensure!(
        mesh.faces.iter().flatten().all(|&i| (i as usize) < n),
        "{name}: a face names a vertex past the {n} vertices"
    );
    let header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment written by alphasurf\n\
         element vertex {n}\nproperty float x\nproperty float y\nproperty float z\n\
         property float nx\nproperty float ny\nproperty float nz\n\
         property float level\nproperty float alpha\n{}\
         element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        if coloured {
            "property uchar red\nproperty uchar green\nproperty uchar blue\n"
        } else {
            ""
        },
        mesh.faces.len()
    );
    crate::io::atomic::write_atomic(path, |w| {
        w.write_all(header.as_bytes())?;
        for i in 0..n {
            let p = mesh.positions[i];
            let nn = mesh.normals[i];
            for v in p.iter().chain(&nn).chain([&mesh.level[i], &mesh.alpha[i]]) {
                w.write_all(&v.to_le_bytes())?;
            }
            if coloured {
                w.write_all(&mesh.colour[i])?;
            }
        }
        for f in &mesh.faces {
            w.write_all(&[3])?;
            for i in f {
                w.write_all(&(*i as i32).to_le_bytes())?;
            }
        }
        Ok(())
    })
}

/// A vertex row as read: x, y, z only.
struct VertexRow([f32; 3]);

impl PropertyAccess for VertexRow {
    fn new() -> Self {
        VertexRow([f32::NAN; 3])
    }
    fn set_float(&mut self, name: &str, v: f32) -> PropertyAccessResult {
        self.set_double(name, v as f64)
    }
    fn set_double(&mut self, name: &str, v: f64) -> PropertyAccessResult {
        match name {
            "x" => self.0[0] = v as f32,
            "y" => self.0[1] = v as f32,
            "z" => self.0[2] = v as f32,
            _ => return PropertyAccessResult::Ignored,
        }
        PropertyAccessResult::Set
    }
}

/// A face row as read: its vertex indices (negative ones kept, to be rejected).
struct FaceRow(Vec<i64>);

impl FaceRow {
    fn set<T: Into<i64>>(&mut self, name: &str, v: Vec<T>) -> PropertyAccessResult {
        if name == "vertex_indices" || name == "vertex_index" {
            self.0 = v.into_iter().map(Into::into).collect();
            PropertyAccessResult::Set
        } else {
            PropertyAccessResult::Ignored
        }
    }
}

impl PropertyAccess for FaceRow {
    fn new() -> Self {
        FaceRow(Vec::new())
    }
    fn set_list_int(&mut self, name: &str, v: Vec<i32>) -> PropertyAccessResult {
        self.set(name, v)
    }
    fn set_list_uint(&mut self, name: &str, v: Vec<u32>) -> PropertyAccessResult {
        self.set(name, v)
    }
    fn set_list_short(&mut self, name: &str, v: Vec<i16>) -> PropertyAccessResult {
        self.set(name, v)
    }
    fn set_list_ushort(&mut self, name: &str, v: Vec<u16>) -> PropertyAccessResult {
        self.set(name, v)
    }
    fn set_list_uchar(&mut self, name: &str, v: Vec<u8>) -> PropertyAccessResult {
        self.set(name, v)
    }
}

/// Whether the PLY at `path` has a non-empty `face` element (is a mesh, not a point cloud).
pub fn has_faces(path: &Path) -> Result<bool> {
    let f =
        std::fs::File::open(path).with_context(|| format!("{}: cannot open", path.display()))?;
    let header = Parser::<VertexRow>::new()
        .read_ply_header(&mut BufReader::new(f))
        .map_err(|e| anyhow::anyhow!("{}: not a valid PLY header: {e}", path.display()))?;
    Ok(header.elements.get("face").is_some_and(|e| e.count > 0))
}

/// Positions and triangles of the PLY mesh at `path` (normals, levels and α left empty).
pub fn read_mesh_ply(path: &Path) -> Result<Mesh> {
    read_inner(path).with_context(|| format!("reading PLY mesh {}", path.display()))
}

fn read_inner(path: &Path) -> Result<Mesh> {
    let name = path.display();
    let f = std::fs::File::open(path).with_context(|| format!("{name}: cannot open"))?;
    let mut reader = Reader::new(BufReader::new(f));
    let vparser = Parser::<VertexRow>::new();
    let fparser = Parser::<FaceRow>::new();
    let header = vparser
        .read_header(&mut reader)
        .map_err(|e| anyhow::anyhow!("{name}: not a valid PLY header: {e}"))?;
    let mut mesh = Mesh::default();
    let mut polygons = Vec::new();
    for (ename, edef) in header.elements.iter() {
        let bad = |e| anyhow::anyhow!("{name}: malformed or truncated '{ename}' data: {e}");
        if ename == "face" {
            polygons = fparser
                .read_payload_for_element(&mut reader, edef, &header)
                .map_err(bad)?;
        } else {
            let rows = vparser
                .read_payload_for_element(&mut reader, edef, &header)
                .map_err(bad)?;
            if ename == "vertex" {
                mesh.positions = rows.into_iter().map(|r| r.0).collect();
            }
        }
    }
    ensure!(!mesh.positions.is_empty(), "{name}: no vertices");
    if let Some(i) = mesh
        .positions
        .iter()
        .position(|p| !p.iter().all(|v| v.is_finite()))
    {
        bail!("{name}: vertex {i} has a missing or non-finite coordinate");
    }
    let n = mesh.positions.len() as i64;
    for (fi, FaceRow(idx)) in polygons.into_iter().enumerate() {
        ensure!(
            idx.len() >= 3,
            "{name}: face {fi} has {} vertices",
            idx.len()
        );
        if let Some(&i) = idx.iter().find(|&&i| !(0..n).contains(&i)) {
            bail!("{name}: face {fi} names vertex {i}, outside 0..{n}");
        }
        for k in 1..idx.len() - 1 {
            mesh.faces
                .push([idx[0] as u32, idx[k] as u32, idx[k + 1] as u32]);
        }
    }
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tetrahedron() -> Mesh {
        Mesh {
            positions: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
            ],
            normals: vec![[0.0, 0.0, 1.0]; 4],
            level: vec![50.0; 4],
            alpha: vec![0.5; 4],
            colour: Vec::new(),
            faces: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        }
    }

    #[test]
    fn round_trip_and_bad_files() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.ply");
        let m = tetrahedron();
        write_mesh_ply(&path, &m).unwrap();
        assert!(has_faces(&path).unwrap());
        let back = read_mesh_ply(&path).unwrap();
        assert_eq!(
            (back.positions, back.faces),
            (m.positions.clone(), m.faces.clone())
        );
        // 4 + 4·8 bytes per vertex, 1 + 3·4 per face after the header.
        let bytes = std::fs::read(&path).unwrap();
        let end = bytes
            .windows(11)
            .position(|w| w == b"end_header\n")
            .unwrap()
            + 11;
        assert_eq!(bytes.len() - end, 4 * 32 + 4 * 13);

        // A NaN coordinate (patched into vertex 1's y) is refused by the reader, and the writer
        // refuses to write one.
        let mut nan = bytes.clone();
        nan[end + 32 + 4..end + 32 + 8].copy_from_slice(&f32::NAN.to_le_bytes());
        std::fs::write(&path, &nan).unwrap();
        let err = format!("{:#}", read_mesh_ply(&path).unwrap_err());
        assert!(
            err.contains("m.ply") && err.contains("vertex 1 has a missing or non-finite"),
            "{err}"
        );
        let mut bad = m.clone();
        bad.normals[2][0] = f32::INFINITY;
        let err = format!("{:#}", write_mesh_ply(&path, &bad).unwrap_err());
        assert!(err.contains("non-finite"), "{err}");

        // A point cloud has no faces.
        let pts = dir.path().join("p.ply");
        crate::io::write_points(&pts, &m.positions).unwrap();
        assert!(!has_faces(&pts).unwrap());

        // Out-of-range index, non-finite vertex: errors naming the file, never a panic.
        let ascii = |body: &str| {
            format!(
                "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
                 property float z\nelement face 1\nproperty list uchar int vertex_indices\n\
                 end_header\n{body}"
            )
        };
        for (body, msg) in [
            ("0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n", "outside 0..3"),
            ("0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n", "outside 0..3"),
            ("0 0 0\n1 0 0\n", "malformed or truncated"),
        ] {
            let bad = dir.path().join("bad.ply");
            std::fs::write(&bad, ascii(body)).unwrap();
            let err = format!("{:#}", read_mesh_ply(&bad).unwrap_err());
            assert!(
                err.contains("bad.ply") && err.contains(msg),
                "{body:?}: {err}"
            );
        }
        // A quad is split into two triangles.
        let quad = dir.path().join("quad.ply");
        let text = ascii("0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
            .replace("vertex 3", "vertex 4")
            .replace("0 1 0\n3 0 1 2", "1 1 0\n0 1 0\n4 0 1 2 3");
        std::fs::write(&quad, text).unwrap();
        assert_eq!(
            read_mesh_ply(&quad).unwrap().faces,
            vec![[0, 1, 2], [0, 2, 3]]
        );

        // Attributes of the wrong length are refused before anything is written.
        let mut short = m.clone();
        short.alpha.pop();
        assert!(write_mesh_ply(&dir.path().join("s.ply"), &short).is_err());
        assert!(!dir.path().join("s.ply").exists());
    }
}
