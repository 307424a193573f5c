//! COLMAP's text model: `cameras.txt` (`ID MODEL WIDTH HEIGHT PARAMS…`), `images.txt` (two lines
//! per image: `ID QW QX QY QZ TX TY TZ CAMERA_ID NAME`, then its 2-D points, possibly empty) and
//! `points3D.txt` (`ID X Y Z R G B ERROR TRACK…`); `#` starts a comment line.

use super::{CameraEntry, ImageEntry};
use crate::data::error::DataError;
use std::path::Path;

fn read(path: &Path) -> Result<String, DataError> {
    std::fs::read_to_string(path).map_err(|e| DataError::Format {
        path: path.to_path_buf(),
        msg: format!("cannot read: {e}"),
    })
}

/// The lines of a text model file with their 1-based numbers, comments dropped (blank lines
/// kept: an image with no 2-D points has an empty second line).
fn lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.starts_with('#'))
}

fn bad(path: &Path, line: usize, msg: String) -> DataError {
    DataError::Format {
        path: path.to_path_buf(),
        msg: format!("line {line}: {msg}"),
    }
}

fn num<T: std::str::FromStr>(
    path: &Path,
    line: usize,
    what: &str,
    s: &str,
) -> Result<T, DataError> {
    s.parse()
        .map_err(|_| bad(path, line, format!("{what} '{s}' is not a number")))
}

/// Reads `cameras.txt`.
pub fn cameras(path: &Path) -> Result<Vec<CameraEntry>, DataError> {
    let text = read(path)?;
    let mut out = Vec::new();
    for (n, l) in lines(&text).filter(|(_, l)| !l.is_empty()) {
        let f: Vec<&str> = l.split_whitespace().collect();
        if f.len() < 4 {
            return Err(bad(
                path,
                n,
                format!("expected 'CAMERA_ID MODEL WIDTH HEIGHT PARAMS…', got '{l}'"),
            ));
        }
        out.push(CameraEntry {
            id: num(path, n, "camera id", f[0])?,
            model: f[1].to_string(),
            width: num(path, n, "width", f[2])?,
            height: num(path, n, "height", f[3])?,
            params: f[4..]
                .iter()
                .map(|s| num(path, n, "parameter", s))
                .collect::<Result<_, _>>()?,
        });
    }
    Ok(out)
}

/// Reads `images.txt`.
pub fn images(path: &Path) -> Result<Vec<ImageEntry>, DataError> {
    let text = read(path)?;
    let mut out = Vec::new();
    let mut it = lines(&text);
    while let Some((n, l)) = it.next() {
        if l.is_empty() {
            continue;
        }
        let f: Vec<&str> = l.split_whitespace().collect();
        if f.len() < 10 {
            return Err(bad(
                path,
                n,
                format!("expected 'IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME', got '{l}'"),
            ));
        }
        let v = |i: usize, what: &str| num::<f64>(path, n, what, f[i]);
        out.push(ImageEntry {
            id: num(path, n, "image id", f[0])?,
            q: [v(1, "QW")?, v(2, "QX")?, v(3, "QY")?, v(4, "QZ")?],
            t: [v(5, "TX")?, v(6, "TY")?, v(7, "TZ")?],
            camera_id: num(path, n, "camera id", f[8])?,
            name: f[9..].join(" "),
        });
        // The 2-D points line (absent at the very end of a file that lists none).
        it.next();
    }
    Ok(out)
}

/// Reads the positions of `points3D.txt`.
pub fn points(path: &Path) -> Result<Vec<[f64; 3]>, DataError> {
    let text = read(path)?;
    let mut out = Vec::new();
    for (n, l) in lines(&text).filter(|(_, l)| !l.is_empty()) {
        let f: Vec<&str> = l.split_whitespace().collect();
        if f.len() < 8 {
            return Err(bad(
                path,
                n,
                format!("expected 'POINT3D_ID X Y Z R G B ERROR TRACK…', got '{l}'"),
            ));
        }
        out.push([
            num(path, n, "X", f[1])?,
            num(path, n, "Y", f[2])?,
            num(path, n, "Z", f[3])?,
        ]);
    }
    Ok(out)
}
