//! A loaded dataset of posed images, whatever its layout on disk ([`Layout`]): the splits, their
//! frames (camera and 8-bit RGBA pixels composited on the run's background), the scene box and
//! what loading cost.
//! The layouts' readers live in `nerf_synthetic`, `colmap` and `idr`.

use super::background::BackgroundMode;
use super::camera::Camera;
use super::foreground::ForegroundBox;
use super::image::RgbaImage;
use super::layout::Layout;
use super::ndc::Space;
use super::scene_box::SceneBox;
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

/// Loader settings.
#[derive(Clone, Copy, Debug)]
pub struct LoadOptions {
    /// Box-downscale factor (1 = full resolution).
    pub downscale: u32,
    /// Scene normalisation; `None` takes the layout's own (NeRF-synthetic: `SceneBox::default()`,
    /// COLMAP: the foreground box without masks, else from the sparse points in view,
    /// instant-ngp: the foreground box, IDR: from `scale_mat`).
    pub scene: Option<SceneBox>,
    /// The colour images with alpha or masks are composited on; `Learned` refuses them
    /// (`DataError::AlphaWithLearnedBackground`).
    pub background: BackgroundMode,
    /// Where the grid lies when `scene` is `None`: the layout's box, or NDC for a
    /// forward-facing capture ([`super::ndc::choose`]).
    pub space: Space,
}

impl Default for LoadOptions {
    fn default() -> Self {
        LoadOptions {
            downscale: 1,
            scene: None,
            background: BackgroundMode::White,
            space: Space::Box,
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

/// What loading cost.
#[derive(Clone, Copy, Debug)]
pub struct LoadReport {
    /// Wall time of the load, seconds.
    pub seconds: f64,
    /// Bytes of pixel data held.
    pub image_bytes: usize,
    /// Number of images held.
    pub n_images: usize,
    /// Peak resident set size of the process after loading (Linux `VmHWM`), if known.
    pub peak_rss_bytes: Option<u64>,
}

/// A loaded dataset.
#[derive(Clone, Debug)]
pub struct Dataset {
    /// The dataset directory.
    pub root: PathBuf,
    /// Its layout on disk.
    pub layout: Layout,
    /// Training views.
    pub train: Split,
    /// Validation views, `None` when the layout has none (no `transforms_val.json`, no `val` list
    /// in a split file): then `val()` is the test split.
    pub val_split: Option<Split>,
    /// Test views.
    pub test: Split,
    /// Scene normalisation.
    pub scene: SceneBox,
    /// Which space the grid lies in and why (`LoadOptions::space`), for `inspect` and the log.
    pub space: String,
    /// The foreground box the layout found from the cameras (captures without masks), whether
    /// or not `scene` was overridden.
    pub foreground: Option<ForegroundBox>,
    /// How the views were split into train, val and test.
    pub split_rule: SplitRule,
    /// The background its images with alpha were composited on (`LoadOptions::background`), and
    /// that training composites on.
    pub background: BackgroundMode,
    /// Load time and memory.
    pub report: LoadReport,
}

impl Dataset {
    /// The validation split (the test split when there is none).
    pub fn val(&self) -> &Split {
        self.val_split.as_ref().unwrap_or(&self.test)
    }

    /// The splits present, in order train, val (if its own file exists), test.
    pub fn splits(&self) -> Vec<&Split> {
        let mut v = vec![&self.train];
        if let Some(s) = &self.val_split {
            v.push(s);
        }
        v.push(&self.test);
        v
    }
}

/// Peak resident set size of this process (`VmHWM` from /proc/self/status), Linux only.
pub fn peak_rss_bytes() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// Splits as a layout's reader returns them: train, val (if any), test.
pub(super) type Splits = (Split, Option<Split>, Split);
