//! Atomic file writes: every output (PLY, PNG, JSON, CSV, npz) is filled into a temporary file in
//! the destination's folder, flushed and fsynced, then renamed over the destination, and the
//! folder is fsynced. A failure at any point (a full disk, a killed process) leaves the previous
//! file as it was: readers see the old file or the new one, never a truncated one. Every error
//! propagates, naming the file.

use anyhow::{Context, Result};
use std::fs::{self, File};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// The temporary a write to `path` fills: `<name>.tmp` beside it (a stale one left by a killed
/// process is overwritten by the next write; a run's lock keeps two writers apart).
pub fn temp_path(path: &Path) -> Result<PathBuf> {
    let name = path
        .file_name()
        .with_context(|| format!("{} has no file name", path.display()))?;
    let mut tmp = name.to_os_string();
    tmp.push(".tmp");
    Ok(path.with_file_name(tmp))
}

/// Write `path` atomically: `fill` writes the contents into a buffered temporary file; on success
/// it is fsynced and renamed over `path`, on any error it is removed and `path` is untouched.
pub fn write_atomic(
    path: &Path,
    fill: impl FnOnce(&mut BufWriter<File>) -> Result<()>,
) -> Result<()> {
    let tmp = temp_path(path)?;
    let result = (|| -> Result<()> {
        let file =
            File::create(&tmp).with_context(|| format!("cannot create {}", tmp.display()))?;
        let mut w = BufWriter::with_capacity(1 << 20, file);
        fill(&mut w)?;
        let file = w.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()?;
        fs::rename(&tmp, path)
            .with_context(|| format!("cannot rename {} over it", tmp.display()))?;
        Ok(())
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result.with_context(|| format!("writing {}", path.display()))?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    File::open(dir)
        .and_then(|d| d.sync_all())
        .with_context(|| format!("syncing directory {}", dir.display()))
}

/// Write `bytes` to `path` atomically.
pub fn write_bytes(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, |w| Ok(w.write_all(bytes)?))
}

/// Write a JSON value (pretty-printed) to `path` atomically.
pub fn write_json(path: &Path, value: &serde_json::Value) -> Result<()> {
    write_bytes(path, &serde_json::to_vec_pretty(value)?)
}

/// Encode 8-bit pixels as PNG and write them to `path` atomically. Sizes whose byte count does
/// not fit the encoder's 32-bit arithmetic are an error, not a panic.
pub fn write_png(
    path: &Path,
    pixels: &[u8],
    width: u32,
    height: u32,
    color: image::ExtendedColorType,
) -> Result<()> {
    use image::ImageEncoder;
    let channels = color.channel_count() as u64;
    let bytes = width as u64 * height as u64 * channels;
    anyhow::ensure!(
        bytes == pixels.len() as u64 && bytes <= u32::MAX as u64,
        "{}: a {width}x{height} image with {channels} channels ({bytes} bytes; {} given) cannot \
         be written as PNG",
        path.display(),
        pixels.len()
    );
    write_atomic(path, |w| {
        image::codecs::png::PngEncoder::new(w)
            .write_image(pixels, width, height, color)
            .context("encoding PNG")
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_write_keeps_the_previous_file_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.ply");
        write_bytes(&path, b"previous").unwrap();
        let err = write_atomic(&path, |w| {
            w.write_all(b"half of the new cont")?;
            anyhow::bail!("disk full (simulated)")
        })
        .unwrap_err();
        assert!(format!("{err:#}").contains("out.ply"), "{err:#}");
        assert_eq!(fs::read(&path).unwrap(), b"previous");
        assert!(!temp_path(&path).unwrap().exists());
        write_bytes(&path, b"new").unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"new");
    }

    #[test]
    fn png_sizes_past_the_encoder_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.png");
        let err = write_png(
            &path,
            &[],
            100_000,
            100_000,
            image::ExtendedColorType::Rgba8,
        );
        assert!(err.is_err());
        assert!(!path.exists());
        write_png(&path, &[1, 2, 3], 1, 1, image::ExtendedColorType::Rgb8).unwrap();
        assert_eq!(image::open(&path).unwrap().width(), 1);
    }
}
