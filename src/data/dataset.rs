//! A loaded dataset of posed images, whatever its layout on disk ([`Layout`]): the splits, their
//! frames (camera and 8-bit RGBA pixels composited on the run's background), the scene box and
//! what loading cost.
//! The layouts' readers live in `nerf_synthetic`, `colmap` and `idr`; the splits they return in
//! `split`.

use super::background::BackgroundMode;
use super::foreground::ForegroundBox;
use super::layout::Layout;
use super::ndc::Space;
use super::scene_box::SceneBox;
use super::split::{Split, SplitRule};
use std::path::PathBuf;

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
            background: BackgroundMode::Auto,
            space: Space::Box,
        }
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
    /// Whether the grid's box is the cube fitted to the foreground box the layout found (not a
    /// box given with `--box`, not NDC).
    pub fn in_foreground_box(&self) -> bool {
        self.foreground
            .as_ref()
            .is_some_and(|f| self.scene == f.bounds.scene_box())
    }

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
