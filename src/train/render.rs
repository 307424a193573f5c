//! Rendering a split through a stage-1 backend: PNG per view and PSNR against the composited
//! targets.

use crate::data::{view_rays, Dataset, Split};
use crate::plenoxel::PlenoxelsBackend;
use crate::stage::psnr;
use anyhow::{Context, Result};
use std::path::Path;

/// Per-view and mean PSNR of a rendered split.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct RenderedSplit {
    pub split: String,
    pub psnr: Vec<f64>,
    pub mean_psnr: f64,
}

/// View `view` of `split` rendered with `per_axis`² rays per pixel, averaged (see
/// [`render_split_with`]); rgb per pixel, row by row.
fn render_averaged(
    render: &mut dyn FnMut(&[f32]) -> Result<Vec<f32>>,
    data: &Dataset,
    split: &Split,
    view: usize,
    per_axis: u32,
) -> Result<Vec<f32>> {
    let camera = &split.frames[view].camera;
    let (w, n) = (split.width() as usize, per_axis as usize);
    let per_pixel = n * n;
    let pixels = w * split.height() as usize;
    let block = (RENDER_CHUNK / per_pixel).max(1);
    let off = |j: usize| (j as f32 + 0.5) / n as f32;
    let mut rgb = Vec::with_capacity(3 * pixels);
    for start in (0..pixels).step_by(block) {
        let end = (start + block).min(pixels);
        let mut rays = Vec::with_capacity(6 * per_pixel * (end - start));
        for p in start..end {
            let (x, y) = ((p % w) as f32, (p / w) as f32);
            for k in 0..per_pixel {
                let (o, d) = camera.ray_at(x + off(k % n), y + off(k / n));
                rays.extend_from_slice(&data.scene.ray(o, d));
            }
        }
        let colours = render(&rays)?;
        for px in colours.chunks_exact(3 * per_pixel) {
            for c in 0..3 {
                let sum: f32 = px
                    .iter()
                    .skip(c)
                    .step_by(3)
                    .map(|v| v.clamp(0.0, 1.0))
                    .sum();
                rgb.push(sum / per_pixel as f32);
            }
        }
    }
    Ok(rgb)
}

/// Render every view of `split` through a stage-1 backend into `out/r_<i>.png` and measure PSNR
/// (`per_axis`: see [`render_split_with`]).
pub fn render_split(
    backend: &mut dyn PlenoxelsBackend,
    data: &Dataset,
    split: &Split,
    stop_thresh: f32,
    out: &Path,
    per_axis: u32,
) -> Result<RenderedSplit> {
    render_split_with(
        &mut |rays| Ok(backend.render(rays, stop_thresh)?.0),
        data,
        split,
        out,
        per_axis,
    )
}

/// Rays per call of the renderer.
const RENDER_CHUNK: usize = 131_072;

/// Largest `per_axis` of [`render_split_with`] (64 rays per pixel).
pub const MAX_PIXEL_SAMPLES: u32 = 8;

/// Render every view of `split` with `render` (rays, 6 floats each → rgb, 3 floats each) into
/// `out/r_<i>.png` and measure PSNR. `per_axis` = 1: one ray through each pixel's centre (what
/// training renders); n > 1: n×n rays on a regular grid inside the pixel (offsets (k + ½)/n),
/// their colours clamped to [0, 1] and averaged: the pixel's mean, as a renderer that filters
/// over the pixel (Cycles) makes the images.
pub fn render_split_with(
    render: &mut dyn FnMut(&[f32]) -> Result<Vec<f32>>,
    data: &Dataset,
    split: &Split,
    out: &Path,
    per_axis: u32,
) -> Result<RenderedSplit> {
    anyhow::ensure!(
        (1..=MAX_PIXEL_SAMPLES).contains(&per_axis),
        "{per_axis}×{per_axis} samples per pixel: 1 to {MAX_PIXEL_SAMPLES} per axis"
    );
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let mut psnrs = Vec::new();
    for (i, frame) in split.frames.iter().enumerate() {
        let b = view_rays(split, &data.scene, i);
        let rgb = if per_axis == 1 {
            let mut rgb = Vec::with_capacity(3 * b.len());
            for chunk in b.flat_rays().chunks(6 * RENDER_CHUNK) {
                rgb.extend(render(chunk)?);
            }
            rgb
        } else {
            render_averaged(render, data, split, i, per_axis)?
        };
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
