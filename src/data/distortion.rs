//! Lens distortion of COLMAP's SIMPLE_RADIAL, RADIAL and OPENCV models (OPENCV with OpenCV's
//! third radial coefficient k3, as instant-ngp and nerfstudio write it), and undistortion of an
//! image onto the pinhole camera with the same focal lengths and principal point.
//!
//! COLMAP's formulation: a point at normalised coordinates (x, y) = ((u − cx)/fx, (v − cy)/fy) of
//! the ideal pinhole image is seen at (x + dx, y + dy) with r² = x² + y², radial factor
//! k1·r² + k2·r⁴ + k3·r⁶ and OpenCV's tangential terms. Undistortion samples the source image there
//! (bilinear, coordinates clamped to the image, so border pixels that the lens did not see repeat
//! the nearest edge); the output has the source's size.

/// A distortion model with its coefficients.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Distortion {
    /// A pinhole camera.
    None,
    /// Radial: k1·r² + k2·r⁴ (SIMPLE_RADIAL has k2 = 0).
    Radial {
        /// r² coefficient.
        k1: f64,
        /// r⁴ coefficient.
        k2: f64,
    },
    /// OpenCV: radial k1, k2, k3 and tangential p1, p2 (COLMAP's OPENCV has k3 = 0).
    OpenCv {
        /// r² coefficient.
        k1: f64,
        /// r⁴ coefficient.
        k2: f64,
        /// r⁶ coefficient.
        k3: f64,
        /// Tangential coefficient.
        p1: f64,
        /// Tangential coefficient.
        p2: f64,
    },
}

impl Distortion {
    /// Where the lens images the ideal normalised point (x, y).
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        let r2 = x * x + y * y;
        match *self {
            Distortion::None => (x, y),
            Distortion::Radial { k1, k2 } => {
                let s = 1.0 + k1 * r2 + k2 * r2 * r2;
                (x * s, y * s)
            }
            Distortion::OpenCv { k1, k2, k3, p1, p2 } => {
                let s = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
                (
                    x * s + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
                    y * s + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
                )
            }
        }
    }

    /// The ideal normalised point the lens images at (xd, yd): [`Distortion::distort`] inverted
    /// by fixed-point iteration (converges for the moderate distortion of real lenses).
    pub fn undistort_point(&self, xd: f64, yd: f64) -> (f64, f64) {
        let (mut x, mut y) = (xd, yd);
        for _ in 0..50 {
            let (dx, dy) = self.distort(x, y);
            (x, y) = (x + xd - dx, y + yd - dy);
        }
        (x, y)
    }

    /// Whether the model is the identity (no coefficients or all zero).
    pub fn is_identity(&self) -> bool {
        match *self {
            Distortion::None => true,
            Distortion::Radial { k1, k2 } => k1 == 0.0 && k2 == 0.0,
            Distortion::OpenCv { k1, k2, k3, p1, p2 } => {
                [k1, k2, k3, p1, p2].iter().all(|&c| c == 0.0)
            }
        }
    }
}

/// Intrinsics in pixels, pixel centres at +0.5 (COLMAP's and our convention).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pinhole {
    /// Focal length x.
    pub fx: f64,
    /// Focal length y.
    pub fy: f64,
    /// Principal point x.
    pub cx: f64,
    /// Principal point y.
    pub cy: f64,
}

impl Pinhole {
    /// The intrinsics of `camera`.
    pub fn of(camera: &super::camera::Camera) -> Pinhole {
        Pinhole {
            fx: camera.fx as f64,
            fy: camera.fy as f64,
            cx: camera.cx as f64,
            cy: camera.cy as f64,
        }
    }
}

/// The RGBA8 image `src` (w × h, straight alpha) seen through the ideal pinhole `k`: each output
/// pixel centre is mapped through `d` and the source sampled bilinearly there.
pub fn undistort(w: u32, h: u32, src: &[u8], k: &Pinhole, d: &Distortion) -> Vec<u8> {
    resample(w, h, src, k, |x, y| d.distort(x, y))
}

/// The inverse of [`undistort`]: the pinhole image `src` as the lens `d` would have imaged it
/// (each output pixel centre mapped through [`Distortion::undistort_point`]). For making
/// distorted test data from exact renders.
pub fn distort(w: u32, h: u32, src: &[u8], k: &Pinhole, d: &Distortion) -> Vec<u8> {
    resample(w, h, src, k, |x, y| d.undistort_point(x, y))
}

/// Each output pixel centre's normalised point mapped through `map`, `src` sampled bilinearly
/// there.
fn resample(
    w: u32,
    h: u32,
    src: &[u8],
    k: &Pinhole,
    map: impl Fn(f64, f64) -> (f64, f64),
) -> Vec<u8> {
    let (wu, hu) = (w as usize, h as usize);
    let mut out = vec![0u8; src.len()];
    let texel = |x: usize, y: usize, c: usize| src[4 * (y * wu + x) + c] as f64;
    for v in 0..hu {
        for u in 0..wu {
            let x = (u as f64 + 0.5 - k.cx) / k.fx;
            let y = (v as f64 + 0.5 - k.cy) / k.fy;
            let (xd, yd) = map(x, y);
            // Continuous source coordinates with pixel centres at integers.
            let sx = (k.fx * xd + k.cx - 0.5).clamp(0.0, (wu - 1) as f64);
            let sy = (k.fy * yd + k.cy - 0.5).clamp(0.0, (hu - 1) as f64);
            let (x0, y0) = (sx.floor() as usize, sy.floor() as usize);
            let (x1, y1) = ((x0 + 1).min(wu - 1), (y0 + 1).min(hu - 1));
            let (fx, fy) = (sx - x0 as f64, sy - y0 as f64);
            for c in 0..4 {
                let top = texel(x0, y0, c) * (1.0 - fx) + texel(x1, y0, c) * fx;
                let bottom = texel(x0, y1, c) * (1.0 - fx) + texel(x1, y1, c) * fx;
                let value = top * (1.0 - fy) + bottom * fy;
                out[4 * (v * wu + u) + c] = value.round().clamp(0.0, 255.0) as u8;
            }
        }
    }
    out
}
