//! COLMAP's binary model (little-endian): `cameras.bin` (u64 count; per camera i32 id, i32 model
//! id, u64 width, u64 height, f64 params — their number fixed by the model), `images.bin` (u64
//! count; per image i32 id, f64 qw qx qy qz tx ty tz, i32 camera id, NUL-terminated name, u64
//! number of 2-D points, 24 bytes each) and `points3D.bin` (u64 count; per point u64 id, f64 xyz,
//! u8 rgb, f64 error, u64 track length, 8 bytes per track element). A file that ends early or
//! has bytes after its declared entries is an error naming the entry.

use super::{CameraEntry, ImageEntry, MODELS};
use crate::data::error::DataError;
use std::path::Path;

/// A bounds-checked little-endian reader over a whole file.
struct Reader<'a> {
    path: &'a Path,
    bytes: Vec<u8>,
    at: usize,
}

impl<'a> Reader<'a> {
    fn open(path: &'a Path) -> Result<Reader<'a>, DataError> {
        let bytes = std::fs::read(path).map_err(|e| DataError::Format {
            path: path.to_path_buf(),
            msg: format!("cannot read: {e}"),
        })?;
        Ok(Reader { path, bytes, at: 0 })
    }

    fn take(&mut self, n: usize, what: &dyn Fn() -> String) -> Result<&[u8], DataError> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        let Some(end) = end else {
            return Err(DataError::Truncated {
                path: self.path.to_path_buf(),
                what: format!("the file ends in {}", what()),
            });
        };
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }

    fn u64(&mut self, what: &dyn Fn() -> String) -> Result<u64, DataError> {
        Ok(u64::from_le_bytes(self.take(8, what)?.try_into().unwrap()))
    }

    fn i32(&mut self, what: &dyn Fn() -> String) -> Result<i32, DataError> {
        Ok(i32::from_le_bytes(self.take(4, what)?.try_into().unwrap()))
    }

    fn f64(&mut self, what: &dyn Fn() -> String) -> Result<f64, DataError> {
        Ok(f64::from_le_bytes(self.take(8, what)?.try_into().unwrap()))
    }

    fn skip(&mut self, count: u64, size: u64, what: &dyn Fn() -> String) -> Result<(), DataError> {
        let n = count
            .checked_mul(size)
            .and_then(|n| usize::try_from(n).ok());
        self.take(n.unwrap_or(usize::MAX), what).map(|_| ())
    }

    fn name(&mut self, what: &dyn Fn() -> String) -> Result<String, DataError> {
        let rest = &self.bytes[self.at..];
        let Some(len) = rest.iter().position(|&b| b == 0) else {
            return Err(DataError::Truncated {
                path: self.path.to_path_buf(),
                what: format!("the file ends in {} (no NUL after the name)", what()),
            });
        };
        let name = String::from_utf8_lossy(&rest[..len]).into_owned();
        self.at += len + 1;
        Ok(name)
    }

    /// The declared entry count, then a check after reading them that nothing follows.
    fn count(&mut self, entries: &str) -> Result<u64, DataError> {
        self.u64(&|| format!("the number of {entries}"))
    }

    fn finish(&self, declared: u64, entries: &str) -> Result<(), DataError> {
        let rest = self.bytes.len() - self.at;
        if rest > 0 {
            return Err(DataError::CountMismatch {
                path: self.path.to_path_buf(),
                msg: format!("{rest} bytes follow the {declared} {entries} the file declares"),
            });
        }
        Ok(())
    }
}

/// Reads `cameras.bin`.
pub fn cameras(path: &Path) -> Result<Vec<CameraEntry>, DataError> {
    let mut r = Reader::open(path)?;
    let n = r.count("cameras")?;
    let mut out = Vec::new();
    for i in 0..n {
        let what = || format!("camera {} of the {n} declared", i + 1);
        let id = r.i32(&what)?;
        let model_id = r.i32(&what)?;
        let Some(&(model, n_params)) = usize::try_from(model_id).ok().and_then(|m| MODELS.get(m))
        else {
            return Err(DataError::CameraModel {
                path: path.to_path_buf(),
                camera_id: id as i64,
                model: format!("id {model_id}"),
                reason: "unknown to COLMAP; the loader reads models 0..=10".into(),
            });
        };
        let width = r.u64(&what)?;
        let height = r.u64(&what)?;
        let params = (0..n_params)
            .map(|_| r.f64(&what))
            .collect::<Result<_, _>>()?;
        out.push(CameraEntry {
            id: id as i64,
            model: model.to_string(),
            width,
            height,
            params,
        });
    }
    r.finish(n, "cameras")?;
    Ok(out)
}

/// Reads `images.bin`.
pub fn images(path: &Path) -> Result<Vec<ImageEntry>, DataError> {
    let mut r = Reader::open(path)?;
    let n = r.count("images")?;
    let mut out = Vec::new();
    for i in 0..n {
        let what = || format!("image {} of the {n} declared", i + 1);
        let id = r.i32(&what)?;
        let mut v = [0f64; 7];
        for x in &mut v {
            *x = r.f64(&what)?;
        }
        let camera_id = r.i32(&what)?;
        let name = r.name(&what)?;
        let what = || format!("the 2-D points of image '{name}' ({} of {n})", i + 1);
        let n_points = r.u64(&what)?;
        r.skip(n_points, 24, &what)?;
        out.push(ImageEntry {
            id: id as i64,
            q: [v[0], v[1], v[2], v[3]],
            t: [v[4], v[5], v[6]],
            camera_id: camera_id as i64,
            name,
        });
    }
    r.finish(n, "images")?;
    Ok(out)
}

/// Reads the positions of `points3D.bin`.
pub fn points(path: &Path) -> Result<Vec<[f64; 3]>, DataError> {
    let mut r = Reader::open(path)?;
    let n = r.count("points")?;
    let mut out = Vec::new();
    for i in 0..n {
        let what = || format!("point {} of the {n} declared", i + 1);
        r.u64(&what)?;
        let p = [r.f64(&what)?, r.f64(&what)?, r.f64(&what)?];
        r.skip(1, 3 + 8, &what)?;
        let track = r.u64(&what)?;
        r.skip(track, 8, &what)?;
        out.push(p);
    }
    r.finish(n, "points")?;
    Ok(out)
}
