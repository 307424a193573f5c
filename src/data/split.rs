//! A dataset's splits as the layouts' readers return them: the views of each split (their image
//! file, camera and pixels) and the rule that made the splits.

use super::camera::Camera;
use super::image::RgbaImage;
use std::path::PathBuf;

/// How a dataset's views were split.
#[derive(Clone, Debug, PartialEq)]
pub enum SplitRule {
    /// One file per split (`transforms_{train,val,test}.json`).
    Files,
    /// The names listed in a split file (`split.json`).
    SplitFile(PathBuf),
    /// Every n-th view by name (the first, the (n+1)-th, …) held out for testing, no validation
    /// split (LLFF's convention).
    EveryNth(usize),
}

impl std::fmt::Display for SplitRule {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SplitRule::Files => f.write_str("one transforms_<split>.json per split"),
            SplitRule::SplitFile(p) => write!(f, "as listed in {}", p.display()),
            SplitRule::EveryNth(n) => write!(
                f,
                "no split file: every {n}th image by name (the first, the {}th, …) held out for \
                 testing (LLFF's convention)",
                n + 1
            ),
        }
    }
}

/// One view: its image file, camera and pixels.
#[derive(Clone, Debug)]
pub struct Frame {
    /// The image file read.
    pub file: PathBuf,
    /// The camera (already adjusted for the downscale).
    pub camera: Camera,
    /// The pixels, composited on the background.
    pub image: RgbaImage,
}

/// One split (train, val or test).
#[derive(Clone, Debug)]
pub struct Split {
    /// "train", "val" or "test".
    pub name: String,
    /// The file that lists its views (`transforms_<split>.json`, a split file, COLMAP's
    /// `images.txt`/`images.bin`, IDR's `cameras_sphere.npz`).
    pub source: PathBuf,
    /// Its views; all of one size.
    pub frames: Vec<Frame>,
}

impl Split {
    /// Image width (all frames share it).
    pub fn width(&self) -> u32 {
        self.frames[0].image.width
    }

    /// Image height.
    pub fn height(&self) -> u32 {
        self.frames[0].image.height
    }

    /// Number of pixels over all views.
    pub fn n_pixels(&self) -> u64 {
        self.frames.len() as u64 * self.width() as u64 * self.height() as u64
    }

    /// Per channel, the median over every view of the pixels on the image border (0..1): the
    /// backdrop's colour when the views frame an object in front of one.
    pub fn border_median(&self) -> [f32; 3] {
        let mut hist = [[0u64; 256]; 3];
        for f in &self.frames {
            let img = &f.image;
            let (w, h) = (img.width, img.height);
            let ring = (0..w)
                .flat_map(|x| [(x, 0), (x, h - 1)])
                .chain((1..h.saturating_sub(1)).flat_map(|y| [(0, y), (w - 1, y)]));
            for (x, y) in ring {
                let p = img.pixel(x, y);
                for c in 0..3 {
                    hist[c][p[c] as usize] += 1;
                }
            }
        }
        hist.map(|hc| {
            let total: u64 = hc.iter().sum();
            let mut seen = 0;
            let level = hc.iter().position(|&n| {
                seen += n;
                2 * seen >= total
            });
            level.unwrap_or(0) as f32 / 255.0
        })
    }
}

/// Splits as a layout's reader returns them: train, val (if any), test.
pub(super) type Splits = (Split, Option<Split>, Split);
