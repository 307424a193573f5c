//! Posed photographs as the COLMAP, IDR, instant-ngp and LLFF readers hand them over, turned into
//! splits: the image folder (`images_2/4/8` when the downscale asks for it and they exist), masks
//! as alpha,
//! undistortion, the held-out split (`split.json`, else every 8th view by name, as in LLFF and
//! mip-NeRF practice) and parallel decoding.

use super::camera::Camera;
use super::distortion::{undistort, Distortion, Pinhole};
use super::error::DataError;
use super::foreground::ForegroundBox;
use super::image::{composite_and_downscale, decode_file, RgbaImage};
use super::scene_box::SceneBox;
use super::split::{Frame, Split, SplitRule, Splits};
use rayon::prelude::*;
use serde::Deserialize;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Without a split file, every `HOLDOUT_EVERY`-th view (sorted by name, starting with the first)
/// is a test view.
pub const HOLDOUT_EVERY: usize = 8;

/// The optional split file in the dataset root: `{"train": [names], "val": [names], "test":
/// [names]}` (`val` optional), names as the model lists the images.
pub const SPLIT_FILE: &str = "split.json";

/// One posed image before decoding.
#[derive(Clone, Debug)]
pub struct View {
    /// The image's name in the model (unique; orders the views).
    pub name: String,
    /// The image file.
    pub file: PathBuf,
    /// Its mask (alpha from the first channel), if the dataset has masks.
    pub mask: Option<PathBuf>,
    /// The full-resolution camera, OpenGL convention, pixel centres at +0.5.
    pub camera: Camera,
    /// Its lens distortion (undistorted on load).
    pub distortion: Distortion,
}

/// What a COLMAP or IDR reader hands over before any image is read.
pub struct Posed {
    /// The posed views.
    pub views: Vec<View>,
    /// Where their images (and masks) are.
    pub folders: Folders,
    /// The file that listed them (named in errors).
    pub source: PathBuf,
    /// The layout's own scene normalisation.
    pub scene: SceneBox,
    /// The foreground box found from the cameras, when the layout looked for one (captures
    /// without masks).
    pub foreground: Option<ForegroundBox>,
    /// The nearest scene depth in front of the cameras, when the layout knows it (sparse points
    /// in view, LLFF's near bounds): where an NDC space puts its near plane (`super::ndc`).
    pub nearest: Option<f32>,
}

/// A layout's splits, its scene normalisation, the foreground box it found (if any) and the
/// nearest scene depth (if known).
pub type Loaded = (Splits, SceneBox, Option<ForegroundBox>, Option<f32>);

impl Posed {
    /// Decodes the views into splits (`k`: the requested downscale; `bg`: the background).
    pub fn load(self, root: &Path, k: u32, bg: [f32; 3]) -> Result<Loaded, DataError> {
        let splits = load_splits(root, &self.source, self.views, &self.folders, k, bg)?;
        Ok((splits, self.scene, self.foreground, self.nearest))
    }

    /// The training split's views, without reading any image.
    pub fn train_views(self, root: &Path) -> Result<Vec<View>, DataError> {
        train_views(root, &self.source, self.views)
    }
}

/// The image and mask folders to read, and the factor they are already downscaled by.
#[derive(Clone, Debug, PartialEq)]
pub struct Folders {
    /// Image folder.
    pub images: PathBuf,
    /// Mask folder, if the dataset has one.
    pub masks: Option<PathBuf>,
    /// 1 for full resolution; k for `images_k`.
    pub prescaled: u32,
}

/// `root/<images>` and `root/<masks>` (if present), or their `_k` variants when `k` is 2, 4 or 8
/// and they exist (masks too, if the dataset has masks).
pub fn folders(root: &Path, images: &str, masks: &str, k: u32) -> Folders {
    let full_masks = root.join(masks);
    let full = Folders {
        images: root.join(images),
        masks: full_masks.is_dir().then_some(full_masks),
        prescaled: 1,
    };
    if ![2, 4, 8].contains(&k) {
        return full;
    }
    let small = root.join(format!("{images}_{k}"));
    let small_masks = root.join(format!("{masks}_{k}"));
    if !small.is_dir() || (full.masks.is_some() && !small_masks.is_dir()) {
        return full;
    }
    Folders {
        images: small,
        masks: full.masks.map(|_| small_masks),
        prescaled: k,
    }
}

/// How [`Posed::load`] splits the views of the dataset `root`.
pub fn split_rule(root: &Path) -> SplitRule {
    let file = root.join(SPLIT_FILE);
    if file.exists() {
        SplitRule::SplitFile(file)
    } else {
        SplitRule::EveryNth(HOLDOUT_EVERY)
    }
}

#[derive(Deserialize)]
struct SplitFile {
    train: Vec<String>,
    #[serde(default)]
    val: Option<Vec<String>>,
    test: Vec<String>,
}

/// Which views make which split: the views sorted by name (duplicates refused), the split file's
/// names when it exists, else every [`HOLDOUT_EVERY`]-th view held out for testing.
struct Assigned {
    train: Vec<usize>,
    val: Option<Vec<usize>>,
    test: Vec<usize>,
    /// The file the assignment comes from (the split file, else `source`), named in errors.
    src: PathBuf,
}

fn assign(root: &Path, source: &Path, views: &mut [View]) -> Result<Assigned, DataError> {
    views.sort_by(|a, b| a.name.cmp(&b.name));
    if let Some(w) = views.windows(2).find(|w| w[0].name == w[1].name) {
        return Err(DataError::CountMismatch {
            path: source.to_path_buf(),
            msg: format!("image '{}' is listed twice", w[0].name),
        });
    }
    let split_file = root.join(SPLIT_FILE);
    if split_file.exists() {
        let (train, val, test) = assign_from_file(&split_file, views)?;
        return Ok(Assigned {
            train,
            val,
            test,
            src: split_file,
        });
    }
    if views.len() < 2 {
        return Err(DataError::CountMismatch {
            path: source.to_path_buf(),
            msg: format!(
                "{} posed image(s): at least 2 are needed (one to train on, one held out)",
                views.len()
            ),
        });
    }
    let (test, train): (Vec<usize>, Vec<usize>) =
        (0..views.len()).partition(|i| i % HOLDOUT_EVERY == 0);
    Ok(Assigned {
        train,
        val: None,
        test,
        src: source.to_path_buf(),
    })
}

/// The training split's views, in the order [`load_splits`] gives them, without reading any
/// image. `source` is the file that listed them (named in errors).
fn train_views(root: &Path, source: &Path, mut views: Vec<View>) -> Result<Vec<View>, DataError> {
    let a = assign(root, source, &mut views)?;
    if a.train.is_empty() {
        return Err(DataError::EmptySplit {
            path: a.src,
            split: "train".into(),
        });
    }
    Ok(a.train.iter().map(|&i| views[i].clone()).collect())
}

/// Loads `views` into splits. `source` is the file that listed them (named in errors); `k` the
/// requested downscale, of which `folders.prescaled` is already done by the files.
fn load_splits(
    root: &Path,
    source: &Path,
    mut views: Vec<View>,
    folders: &Folders,
    k: u32,
    bg: [f32; 3],
) -> Result<Splits, DataError> {
    let Assigned {
        train,
        val,
        test,
        src,
    } = assign(root, source, &mut views)?;
    let split = |name: &str, idx: Vec<usize>| -> Result<Split, DataError> {
        if idx.is_empty() {
            return Err(DataError::EmptySplit {
                path: src.clone(),
                split: name.into(),
            });
        }
        let frames: Vec<Result<Frame, DataError>> = idx
            .par_iter()
            .map(|&i| load_view(&views[i], source, folders, k, bg))
            .collect();
        Ok(Split {
            name: name.into(),
            source: src.clone(),
            frames: frames.into_iter().collect::<Result<_, _>>()?,
        })
    };
    let train = split("train", train)?;
    let val = val.map(|v| split("val", v)).transpose()?;
    let test = split("test", test)?;
    Ok((train, val, test))
}

type Assignment = (Vec<usize>, Option<Vec<usize>>, Vec<usize>);

/// The view indices the split file names, per split.
fn assign_from_file(path: &Path, views: &[View]) -> Result<Assignment, DataError> {
    let text = std::fs::read_to_string(path).map_err(|e| DataError::Format {
        path: path.to_path_buf(),
        msg: format!("cannot read: {e}"),
    })?;
    let file: SplitFile = serde_json::from_str(&text).map_err(|e| DataError::Json {
        path: path.to_path_buf(),
        line: e.line(),
        column: e.column(),
        msg: e.to_string(),
    })?;
    let index: HashMap<&str, usize> = views
        .iter()
        .enumerate()
        .map(|(i, v)| (v.name.as_str(), i))
        .collect();
    let look = |split: &str, names: &[String]| -> Result<Vec<usize>, DataError> {
        names
            .iter()
            .map(|n| {
                index
                    .get(n.as_str())
                    .copied()
                    .ok_or_else(|| DataError::Format {
                        path: path.to_path_buf(),
                        msg: format!("'{split}' names image '{n}', which the model does not pose"),
                    })
            })
            .collect()
    };
    let val = file.val.as_deref().map(|v| look("val", v)).transpose()?;
    Ok((look("train", &file.train)?, val, look("test", &file.test)?))
}

/// Decodes one view: image (+ mask as alpha), undistorted, composited on `bg`, downscaled.
fn load_view(
    v: &View,
    source: &Path,
    folders: &Folders,
    k: u32,
    bg: [f32; 3],
) -> Result<Frame, DataError> {
    // Not there, or there but unreadable (a folder, a link loop): said as such.
    let missing = |path: &Path| match super::image::unreadable_reason(path) {
        Some(why) => DataError::UnreadableImage {
            path: path.to_path_buf(),
            msg: format!("{why} (image '{}' posed in {})", v.name, source.display()),
        },
        None => DataError::MissingViewFile {
            path: path.to_path_buf(),
            image: v.name.clone(),
            listed_in: source.to_path_buf(),
        },
    };
    if !v.file.is_file() {
        return Err(missing(&v.file));
    }
    let (w, h, mut raw, mut had_alpha) = decode_file(&v.file)?;
    let mut cam = v.camera;
    let p = folders.prescaled;
    let expected = |full: u32| [full / p, full.div_ceil(p)];
    if !expected(cam.width).contains(&w) || !expected(cam.height).contains(&h) {
        return Err(DataError::MixedSizes {
            path: v.file.clone(),
            got_w: w,
            got_h: h,
            reference: format!(
                "{} (camera of '{}'{})",
                source.display(),
                v.name,
                if p > 1 {
                    format!(", divided by {p}")
                } else {
                    String::new()
                }
            ),
            want_w: cam.width / p,
            want_h: cam.height / p,
        });
    }
    if p > 1 {
        let (sx, sy) = (w as f32 / cam.width as f32, h as f32 / cam.height as f32);
        cam = Camera {
            fx: cam.fx * sx,
            fy: cam.fy * sy,
            cx: cam.cx * sx,
            cy: cam.cy * sy,
            width: w,
            height: h,
            ..cam
        };
    }
    if let Some(mask) = &v.mask {
        if !mask.is_file() {
            return Err(missing(mask));
        }
        let (mw, mh, m, _) = decode_file(mask)?;
        if (mw, mh) != (w, h) {
            return Err(DataError::MixedSizes {
                path: mask.clone(),
                got_w: mw,
                got_h: mh,
                reference: v.file.display().to_string(),
                want_w: w,
                want_h: h,
            });
        }
        for (px, mp) in raw.chunks_exact_mut(4).zip(m.chunks_exact(4)) {
            px[3] = mp[0];
        }
        had_alpha = true;
    }
    if !v.distortion.is_identity() {
        raw = undistort(w, h, &raw, &Pinhole::of(&cam), &v.distortion);
    }
    let k_rest = k / p;
    if w / k_rest == 0 || h / k_rest == 0 {
        return Err(DataError::BadDownscale {
            path: v.file.clone(),
            factor: k,
            reason: format!("the image is only {w}x{h}"),
        });
    }
    let (ow, oh, data) = composite_and_downscale(w, h, &raw, k_rest, bg);
    Ok(Frame {
        file: v.file.clone(),
        camera: cam.downscaled(k_rest),
        image: RgbaImage {
            width: ow,
            height: oh,
            data,
            had_alpha,
        },
    })
}
