//! Training checkpoints: the grid (svox2 arrays at the top level, so svox2 and
//! [`super::npz::load_svox2`] read it as a plain checkpoint), named optimiser-state arrays
//! (`optim_<name>`, float32 1-D) and a JSON metadata blob (`alphasurf_meta`, uint8 UTF-8 bytes:
//! step, stage, config — opaque here) in one npz, written atomically (see [`super::npz::write_atomic`]).
//! Loading validates the grid as an svox2 import does, and the optimiser arrays for finiteness;
//! their lengths are the caller's to check.

use std::path::Path;

use anyhow::{bail, ensure, Context, Result};

use crate::grid::npz::{self, Data, NpzReader};
use crate::grid::Grid;

/// Name of the metadata array.
pub const META: &str = "alphasurf_meta";
/// Prefix of the optimiser-state arrays.
pub const OPTIM_PREFIX: &str = "optim_";

/// A loaded checkpoint.
#[derive(Debug, Clone, PartialEq)]
pub struct Checkpoint {
    pub grid: Grid,
    /// Optimiser state by name, in file order.
    pub optim: OptimArrays,
    pub meta: serde_json::Value,
}

fn check_name(name: &str) -> Result<()> {
    ensure!(
        !name.is_empty() && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_'),
        "optimiser array name '{name}' must be non-empty [A-Za-z0-9_]"
    );
    Ok(())
}

/// Named optimiser-state arrays to write, borrowed (a checkpoint of a 512³ grid would otherwise
/// copy gigabytes).
pub type OptimRefs<'a> = [(&'a str, &'a [f32])];

/// Write a checkpoint atomically to `path`. Refuses (leaving any previous checkpoint intact) an
/// invalid or non-finite grid, non-finite optimiser state, or bad/duplicate names.
pub fn save(path: &Path, grid: &Grid, optim: &OptimRefs, meta: &serde_json::Value) -> Result<()> {
    write(path, grid, optim, meta).with_context(|| format!("saving checkpoint {}", path.display()))
}

fn write(path: &Path, grid: &Grid, optim: &OptimRefs, meta: &serde_json::Value) -> Result<()> {
    check_optim(optim)?;
    let meta = serde_json::to_vec(meta)?;
    npz::write_atomic(path, |w| {
        npz::write_grid(w, grid)?;
        write_extras(w, optim, &meta)
    })
}

/// Refuse bad or duplicate optimiser-array names and non-finite optimiser state.
pub(crate) fn check_optim(optim: &OptimRefs) -> Result<()> {
    for (i, (name, v)) in optim.iter().enumerate() {
        check_name(name)?;
        ensure!(
            optim[..i].iter().all(|(n, _)| n != name),
            "optimiser array '{name}' given twice"
        );
        if let Some(j) = v.iter().position(|x| !x.is_finite()) {
            bail!("optimiser array '{name}': non-finite value {} at {j}", v[j]);
        }
    }
    Ok(())
}

/// Add the optimiser arrays and the metadata (JSON bytes) to an npz being written.
pub(crate) fn write_extras<W: std::io::Write + std::io::Seek>(
    w: &mut npz::NpzWriter<W>,
    optim: &OptimRefs,
    meta: &[u8],
) -> Result<()> {
    for (name, v) in optim {
        w.array(&format!("{OPTIM_PREFIX}{name}"), &[v.len() as u64], v)?;
    }
    w.array(META, &[meta.len() as u64], meta)
}

/// Load and validate a checkpoint written by [`save`].
pub fn load(path: &Path) -> Result<Checkpoint> {
    let mut r = NpzReader::open(path)?;
    read(&mut r).with_context(|| format!("loading checkpoint {}", path.display()))
}

/// The metadata of the npz at `path`: `None` when it has none (an svox2 `ckpt.npz`).
pub fn read_meta(path: &Path) -> Result<Option<serde_json::Value>> {
    let mut r = NpzReader::open(path)?;
    if !r.contains(META) {
        return Ok(None);
    }
    let meta = match r.read(META)?.data {
        Data::U8(bytes) => serde_json::from_slice(&bytes)
            .with_context(|| format!("{}: array '{META}' is not valid JSON", path.display()))?,
        d => bail!(
            "{}: array '{META}' has dtype {}, expected uint8",
            path.display(),
            d.kind()
        ),
    };
    Ok(Some(meta))
}

fn read(r: &mut NpzReader) -> Result<Checkpoint> {
    ensure!(
        r.contains(META),
        "no '{META}' array: not an alphasurf checkpoint (an svox2 ckpt.npz is imported with \
         npz::load_svox2)"
    );
    let grid = npz::read_grid(r)?;
    let (optim, meta) = read_extras(r)?;
    Ok(Checkpoint { grid, optim, meta })
}

/// The arrays `names` among the optimiser-state arrays of the checkpoint at `path` (those it
/// has, validated as [`load`] does), without reading the rest.
pub fn read_named(path: &Path, names: &[&str]) -> Result<OptimArrays> {
    let mut r = NpzReader::open(path)?;
    let mut out = Vec::new();
    for name in names {
        let array = format!("{OPTIM_PREFIX}{name}");
        if !r.contains(&array) {
            continue;
        }
        let a = r
            .read(&array)
            .with_context(|| format!("{}", path.display()))?;
        ensure!(
            a.shape.len() == 1,
            "{}: array '{array}' has shape {:?}, expected 1-D",
            path.display(),
            a.shape
        );
        let v = a.into_f32(&array)?;
        if let Some(j) = v.iter().position(|x| !x.is_finite()) {
            bail!(
                "{}: array '{array}': non-finite value {} at {j}",
                path.display(),
                v[j]
            );
        }
        out.push((name.to_string(), v));
    }
    Ok(out)
}

/// Named optimiser-state arrays, in file order.
pub type OptimArrays = Vec<(String, Vec<f32>)>;

/// Borrow loaded arrays for writing them again.
pub fn optim_refs(optim: &OptimArrays) -> Vec<(&str, &[f32])> {
    optim.iter().map(|(n, v)| (n.as_str(), &v[..])).collect()
}

/// The optimiser arrays (validated 1-D and finite) and the metadata of an open checkpoint.
pub(crate) fn read_extras(r: &mut NpzReader) -> Result<(OptimArrays, serde_json::Value)> {
    let meta = match r.read(META)?.data {
        Data::U8(bytes) => serde_json::from_slice(&bytes)
            .with_context(|| format!("array '{META}' is not valid JSON"))?,
        d => bail!("array '{META}' has dtype {}, expected uint8", d.kind()),
    };
    let mut optim = Vec::new();
    for array in r.names() {
        let Some(name) = array.strip_prefix(OPTIM_PREFIX) else {
            continue;
        };
        let a = r.read(&array)?;
        ensure!(
            a.shape.len() == 1,
            "array '{array}' has shape {:?}, expected 1-D",
            a.shape
        );
        let v = a.into_f32(&array)?;
        if let Some(j) = v.iter().position(|x| !x.is_finite()) {
            bail!("array '{array}': non-finite value {} at {j}", v[j]);
        }
        optim.push((name.to_owned(), v));
    }
    Ok((optim, meta))
}

/// The step and configuration of a checkpoint's metadata, which must say `stage`.
pub fn meta_step_config<C: serde::de::DeserializeOwned>(
    meta: &serde_json::Value,
    stage: &str,
    path: &Path,
) -> Result<(u32, C)> {
    if meta["stage"] != stage {
        bail!("{} is not a {stage} checkpoint", path.display());
    }
    let step = meta["step"]
        .as_u64()
        .with_context(|| format!("{}: metadata has no step", path.display()))?;
    let cfg = serde_json::from_value(meta["config"].clone())
        .with_context(|| format!("{}: metadata has no valid config", path.display()))?;
    Ok((step as u32, cfg))
}

/// The optimiser array `name` of a loaded checkpoint.
pub fn optim_array(optim: &[(String, Vec<f32>)], name: &str, path: &Path) -> Result<Vec<f32>> {
    optim
        .iter()
        .find(|(n, _)| n == name)
        .map(|(_, v)| v.clone())
        .with_context(|| format!("{}: no optimiser array {name}", path.display()))
}
