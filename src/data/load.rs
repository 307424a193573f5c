//! Loading a dataset directory: detect its layout, call that layout's reader, check that every
//! split has one image size, and measure the load.

use super::dataset::{peak_rss_bytes, Dataset, LoadOptions, LoadReport};
use super::error::DataError;
use super::layout::{self, Layout};
use super::scene_box::SceneBox;
use super::split::SplitRule;
use anyhow::Context;
use glam::Mat4;
use std::path::Path;
use std::time::Instant;

impl Dataset {
    /// Loads a dataset directory of any supported layout. Errors are [`DataError`]s with context.
    pub fn load(root: &Path, opts: &LoadOptions) -> anyhow::Result<Dataset> {
        load(root, opts).with_context(|| format!("loading dataset {}", root.display()))
    }

    /// The training split's camera-to-world poses, the same views in the same order as
    /// [`Dataset::load`] gives them, without decoding any image (IDR reads the images' headers for
    /// their sizes): for what needs only where the cameras stand, such as extraction's
    /// hidden-surface trim, on captures too large to load for that.
    pub fn train_poses(root: &Path) -> anyhow::Result<Vec<Mat4>> {
        train_poses(root)
            .with_context(|| format!("reading the cameras of dataset {}", root.display()))
    }
}

fn train_poses(root: &Path) -> Result<Vec<Mat4>, DataError> {
    if !root.is_dir() {
        return Err(DataError::MissingDir {
            path: root.to_path_buf(),
        });
    }
    let views = match layout::detect(root)? {
        Layout::NerfSynthetic => return super::nerf_synthetic::train_poses(root),
        Layout::Colmap { sparse, .. } => {
            super::colmap::posed(root, &sparse, 1)?.train_views(root)?
        }
        Layout::Idr => super::idr::posed(root, 1)?.train_views(root)?,
        Layout::InstantNgp => super::instant_ngp::posed(root, 1)?.train_views(root)?,
        Layout::Llff => super::llff::posed(root, 1)?.train_views(root)?,
    };
    Ok(views.iter().map(|v| v.camera.c2w).collect())
}

fn load(root: &Path, opts: &LoadOptions) -> Result<Dataset, DataError> {
    let t0 = Instant::now();
    if !root.is_dir() {
        return Err(DataError::MissingDir {
            path: root.to_path_buf(),
        });
    }
    let k = opts.downscale;
    if k == 0 {
        return Err(DataError::BadDownscale {
            path: root.to_path_buf(),
            factor: 0,
            reason: "the factor must be at least 1".into(),
        });
    }
    let layout = layout::detect(root)?;
    let bg = opts.background.initial_rgb();
    let ((train, val_split, test), scene, foreground, nearest) = match &layout {
        Layout::NerfSynthetic => (
            super::nerf_synthetic::load_splits(root, k, bg)?,
            SceneBox::default(),
            None,
            None,
        ),
        Layout::Colmap { sparse, .. } => {
            super::colmap::posed(root, sparse, k)?.load(root, k, bg)?
        }
        Layout::Idr => super::idr::posed(root, k)?.load(root, k, bg)?,
        Layout::InstantNgp => super::instant_ngp::posed(root, k)?.load(root, k, bg)?,
        Layout::Llff => super::llff::posed(root, k)?.load(root, k, bg)?,
    };
    let split_rule = match layout {
        Layout::NerfSynthetic => SplitRule::Files,
        _ => super::views::split_rule(root),
    };
    // A learned background is for images without alpha: where alpha (or a mask) says which
    // pixels are background, its colour is known and white or black composites them exactly,
    // while a learned colour could fit the composited pixels only by matching the colour they
    // were composited on, and the mask would be thrown away.
    if opts.background.learned() {
        let all = [Some(&train), val_split.as_ref(), Some(&test)];
        if let Some(f) = all
            .into_iter()
            .flatten()
            .flat_map(|s| &s.frames)
            .find(|f| f.image.had_alpha)
        {
            return Err(DataError::AlphaWithLearnedBackground {
                path: root.to_path_buf(),
                image: f.file.clone(),
                mode: opts.background.name(),
            });
        }
    }
    // One image size for the whole dataset.
    let (w, h) = (train.width(), train.height());
    for s in [Some(&test), val_split.as_ref()].into_iter().flatten() {
        let f = &s.frames[0];
        if (f.image.width, f.image.height) != (w, h) {
            return Err(DataError::MixedSizes {
                path: f.file.clone(),
                got_w: f.image.width,
                got_h: f.image.height,
                reference: format!("{} (train)", train.frames[0].file.display()),
                want_w: w,
                want_h: h,
            });
        }
    }
    let (scene, space) = match opts.scene {
        Some(given) if given.ndc.is_some() => (given, "NDC (the run's)".to_string()),
        Some(given) => (given, "box (given)".to_string()),
        None => {
            let cameras: Vec<_> = train.frames.iter().map(|f| f.camera).collect();
            match super::ndc::choose(opts.space, &cameras, nearest) {
                Ok((Some(ndc), why)) => (SceneBox::in_ndc(ndc), why),
                Ok((None, why)) => (scene, why),
                Err(msg) => {
                    return Err(DataError::Format {
                        path: root.to_path_buf(),
                        msg,
                    })
                }
            }
        }
    };
    let all = [Some(&train), val_split.as_ref(), Some(&test)];
    let had_alpha = all
        .iter()
        .flatten()
        .flat_map(|s| &s.frames)
        .any(|f| f.image.had_alpha);
    let background = opts.background.resolve(had_alpha, scene.ndc.is_some());
    let splits = all.iter().flatten();
    let image_bytes = splits
        .clone()
        .flat_map(|s| &s.frames)
        .map(|f| f.image.bytes())
        .sum();
    let n_images = splits.map(|s| s.frames.len()).sum();
    Ok(Dataset {
        root: root.to_path_buf(),
        layout,
        train,
        val_split,
        test,
        scene,
        space,
        foreground,
        split_rule,
        background,
        report: LoadReport {
            seconds: t0.elapsed().as_secs_f64(),
            image_bytes,
            n_images,
            peak_rss_bytes: peak_rss_bytes(),
        },
    })
}
