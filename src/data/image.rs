//! Compact 8-bit RGBA images: decoding (PNG/JPEG via the image crate, turned upright by the
//! file's EXIF orientation as photo viewers show it), compositing on the run's background colour
//! and box downscaling. Colour channels are stored already composited
//! (rgb·a + (1 − a)·bg); the alpha channel keeps the coverage for masks.

use super::error::DataError;
use image::metadata::Orientation;
use image::ImageDecoder;
use std::path::Path;

/// An 8-bit RGBA image, row-major, top row first; RGB composited on the background.
#[derive(Clone, Debug, PartialEq)]
pub struct RgbaImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width·height·4` bytes.
    pub data: Vec<u8>,
    /// Whether the source file had an alpha channel (if not, alpha is 255 everywhere).
    pub had_alpha: bool,
}

impl RgbaImage {
    /// The four bytes of pixel (x, y).
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 4] {
        let i = 4 * (y as usize * self.width as usize + x as usize);
        [
            self.data[i],
            self.data[i + 1],
            self.data[i + 2],
            self.data[i + 3],
        ]
    }

    /// Alpha of pixel (x, y) in [0, 1].
    pub fn alpha(&self, x: u32, y: u32) -> f32 {
        self.pixel(x, y)[3] as f32 / 255.0
    }

    /// Composited colour of pixel (x, y) in [0, 1].
    pub fn rgb(&self, x: u32, y: u32) -> [f32; 3] {
        let p = self.pixel(x, y);
        [
            p[0] as f32 / 255.0,
            p[1] as f32 / 255.0,
            p[2] as f32 / 255.0,
        ]
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.data.len()
    }
}

/// Decodes an image file (format guessed from its content) into straight-alpha RGBA8, without
/// compositing. Errors name the file.
pub fn decode_file(path: &Path) -> Result<(u32, u32, Vec<u8>, bool), DataError> {
    let bytes = std::fs::read(path).map_err(|e| DataError::UnreadableImage {
        path: path.to_path_buf(),
        msg: e.to_string(),
    })?;
    decode_bytes(&bytes).map_err(|msg| DataError::UnreadableImage {
        path: path.to_path_buf(),
        msg,
    })
}

/// Decodes image bytes (PNG or JPEG) into straight-alpha RGBA8, upright by its EXIF orientation:
/// (width, height, data, had_alpha).
pub fn decode_bytes(bytes: &[u8]) -> Result<(u32, u32, Vec<u8>, bool), String> {
    let reader = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| e.to_string())?;
    if reader.format().is_none() {
        return Err("not a PNG or JPEG file".into());
    }
    let mut decoder = reader.into_decoder().map_err(|e| e.to_string())?;
    let orientation = decoder.orientation().map_err(|e| e.to_string())?;
    let mut img = image::DynamicImage::from_decoder(decoder).map_err(|e| e.to_string())?;
    img.apply_orientation(orientation);
    let had_alpha = img.color().has_alpha();
    let rgba = img.to_rgba8();
    let (w, h) = rgba.dimensions();
    if w == 0 || h == 0 {
        return Err("image has no pixels".into());
    }
    Ok((w, h, rgba.into_raw(), had_alpha))
}

/// An image file's size as [`decode_file`] gives it (EXIF orientation applied), from its header.
pub fn image_size(path: &Path) -> Result<(u32, u32), DataError> {
    let unreadable = |msg: String| DataError::UnreadableImage {
        path: path.to_path_buf(),
        msg,
    };
    let mut decoder = image::ImageReader::open(path)
        .map_err(|e| unreadable(e.to_string()))?
        .with_guessed_format()
        .map_err(|e| unreadable(e.to_string()))?
        .into_decoder()
        .map_err(|e| unreadable(e.to_string()))?;
    let (w, h) = decoder.dimensions();
    let turned = matches!(
        decoder
            .orientation()
            .map_err(|e| unreadable(e.to_string()))?,
        Orientation::Rotate90
            | Orientation::Rotate270
            | Orientation::Rotate90FlipH
            | Orientation::Rotate270FlipH
    );
    Ok(if turned { (h, w) } else { (w, h) })
}

/// Why `path`, which is not a readable file, cannot be read (a folder, a symbolic link loop, no
/// permission); `None` when it does not exist (the caller's "not found") or is a file.
pub fn unreadable_reason(path: &std::path::Path) -> Option<String> {
    match std::fs::metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        Err(e) => Some(e.to_string()),
        Ok(m) if m.is_dir() => Some("a folder, not an image".into()),
        Ok(_) => None,
    }
}

/// Composites straight-alpha RGBA8 on `bg`, then box-averages k×k blocks (the ragged right and
/// bottom remainders are dropped). Alpha is box-averaged too. Results are rounded to 8 bits.
pub fn composite_and_downscale(
    w: u32,
    h: u32,
    src: &[u8],
    k: u32,
    bg: [f32; 3],
) -> (u32, u32, Vec<u8>) {
    let k = k.max(1);
    let (ow, oh) = (w / k, h / k);
    let mut out = vec![0u8; ow as usize * oh as usize * 4];
    let inv = 1.0 / (k * k) as f32;
    for oy in 0..oh {
        for ox in 0..ow {
            let mut acc = [0f32; 4];
            for dy in 0..k {
                for dx in 0..k {
                    let i = 4 * ((oy * k + dy) as usize * w as usize + (ox * k + dx) as usize);
                    let a = src[i + 3] as f32 / 255.0;
                    for c in 0..3 {
                        acc[c] += src[i + c] as f32 / 255.0 * a + (1.0 - a) * bg[c];
                    }
                    acc[3] += a;
                }
            }
            let o = 4 * (oy as usize * ow as usize + ox as usize);
            for c in 0..4 {
                out[o + c] = (acc[c] * inv * 255.0).round().clamp(0.0, 255.0) as u8;
            }
        }
    }
    (ow, oh, out)
}
