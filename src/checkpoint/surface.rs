//! The stage-2 (surface) checkpoint: the surface grid's arrays (`links`, `delta_data`,
//! `opacity_data`, `sh_data`, `levels`, `radius`, `center`, `gradient_scale`), the named
//! optimiser arrays and the metadata of [`super::format`], in one npz written atomically.

use super::format::{check_optim, read_extras, write_extras, OptimArrays, OptimRefs, META};
use crate::grid::npz::{self, Data, NpzReader};
use crate::grid::surface::SurfaceGrid;
use crate::grid::SH_DIM;
use anyhow::{bail, ensure, Context, Result};
use std::path::Path;

/// A loaded stage-2 checkpoint.
#[derive(Debug, Clone, PartialEq)]
pub struct SurfaceCheckpoint {
    pub grid: SurfaceGrid,
    /// Optimiser state by name, in file order.
    pub optim: OptimArrays,
    pub meta: serde_json::Value,
}

/// Write a checkpoint atomically (temp file, fsync, rename): the grid, named optimiser arrays
/// and JSON metadata. Refuses invalid or non-finite data, leaving the previous file intact.
pub fn save(
    path: &Path,
    grid: &SurfaceGrid,
    optim: &OptimRefs,
    meta: &serde_json::Value,
) -> Result<()> {
    (|| -> Result<()> {
        grid.validate()?;
        check_optim(optim)?;
        let meta = serde_json::to_vec(meta)?;
        let n = grid.delta.len() as u64;
        npz::write_atomic(path, |w| {
            w.array("links", &grid.res.map(u64::from), &grid.links)?;
            w.array("delta_data", &[n], &grid.delta)?;
            w.array("opacity_data", &[n], &grid.opacity)?;
            w.array("sh_data", &[n, SH_DIM as u64], &grid.sh)?;
            w.array("levels", &[grid.levels.len() as u64], &grid.levels)?;
            w.array("radius", &[3], &grid.radius)?;
            w.array("center", &[3], &grid.center)?;
            w.array("gradient_scale", &[1], &[grid.gradient_scale])?;
            write_extras(w, optim, &meta)
        })
    })()
    .with_context(|| format!("saving surface checkpoint {}", path.display()))
}

/// Load and validate a checkpoint written by [`save`].
pub fn load(path: &Path) -> Result<SurfaceCheckpoint> {
    let mut r = NpzReader::open(path)?;
    read_checkpoint(&mut r)
        .with_context(|| format!("loading surface checkpoint {}", path.display()))
}

fn read_checkpoint(r: &mut NpzReader) -> Result<SurfaceCheckpoint> {
    ensure!(
        r.contains("delta_data") && r.contains(META),
        "no 'delta_data' or '{META}' array: not a stage-2 (surface) checkpoint"
    );
    let links = r.read("links")?;
    let Data::I32(links_v) = links.data else {
        bail!(
            "array 'links' has dtype {}, expected int32",
            links.data.kind()
        );
    };
    ensure!(
        links.shape.len() == 3 && links.shape.iter().all(|&d| d <= 4096),
        "array 'links' has shape {:?}, expected (N, N, N)",
        links.shape
    );
    let mut f32s = |name: &str| -> Result<Vec<f32>> { r.read(name)?.into_f32(name) };
    let vec3 = |v: Vec<f32>, name: &str| -> Result<[f32; 3]> {
        ensure!(
            v.len() == 3,
            "array '{name}' has {} values, expected 3",
            v.len()
        );
        Ok([v[0], v[1], v[2]])
    };
    let grid = SurfaceGrid {
        res: [0, 1, 2].map(|i| links.shape[i] as u32),
        links: links_v.into_iter().map(|l| l.max(-1)).collect(),
        delta: f32s("delta_data")?,
        opacity: f32s("opacity_data")?,
        sh: f32s("sh_data")?,
        levels: f32s("levels")?,
        radius: vec3(f32s("radius")?, "radius")?,
        center: vec3(f32s("center")?, "center")?,
        gradient_scale: *f32s("gradient_scale")?
            .first()
            .context("empty gradient_scale")?,
    };
    grid.validate()?;
    let (optim, meta) = read_extras(r)?;
    Ok(SurfaceCheckpoint { grid, optim, meta })
}
