//! Rendering a split through a stage-1 backend: PNG per view and PSNR against the composited
//! targets.

use crate::data::{view_rays, Dataset, Split};
use crate::plenoxel::Plenoxels;
use anyhow::{Context, Result};
use std::path::Path;

/// Per-view and mean PSNR of a rendered split.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct RenderedSplit {
    pub split: String,
    pub psnr: Vec<f64>,
    pub mean_psnr: f64,
}

/// PSNR in dB of a mean squared error on [0, 1] colours.
pub fn psnr(mse: f64) -> f64 {
    -10.0 * mse.max(1e-20).log10()
}

/// Render every view of `split` through a stage-1 backend into `out/r_<i>.png` and measure PSNR.
pub fn render_split(
    backend: &mut dyn Plenoxels,
    data: &Dataset,
    split: &Split,
    stop_thresh: f32,
    out: &Path,
) -> Result<RenderedSplit> {
    render_split_with(
        &mut |rays| Ok(backend.render(rays, stop_thresh)?.0),
        data,
        split,
        out,
    )
}

/// Render every view of `split` with `render` (rays, 6 floats each → rgb, 3 floats each) into
/// `out/r_<i>.png` and measure PSNR.
pub fn render_split_with(
    render: &mut dyn FnMut(&[f32]) -> Result<Vec<f32>>,
    data: &Dataset,
    split: &Split,
    out: &Path,
) -> Result<RenderedSplit> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let mut psnrs = Vec::new();
    for (i, frame) in split.frames.iter().enumerate() {
        let b = view_rays(split, &data.scene, i);
        let rays = b.flat_rays();
        let mut rgb = Vec::with_capacity(3 * b.len());
        for chunk in rays.chunks(6 * 131_072) {
            rgb.extend(render(chunk)?);
        }
        let mse = rgb
            .iter()
            .zip(b.rgb.iter().flatten())
            .map(|(&a, &t)| ((a.clamp(0.0, 1.0) - t) as f64).powi(2))
            .sum::<f64>()
            / rgb.len() as f64;
        psnrs.push(psnr(mse));
        let bytes: Vec<u8> = rgb
            .iter()
            .map(|&v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
            .collect();
        let path = out.join(format!("r_{i}.png"));
        crate::io::atomic::write_png(
            &path,
            &bytes,
            split.width(),
            split.height(),
            image::ExtendedColorType::Rgb8,
        )
        .with_context(|| format!("view {}", frame.file.display()))?;
    }
    let mean_psnr = psnrs.iter().sum::<f64>() / psnrs.len().max(1) as f64;
    Ok(RenderedSplit {
        split: split.name.clone(),
        psnr: psnrs,
        mean_psnr,
    })
}
