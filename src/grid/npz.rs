//! svox2 checkpoint import/export (`ckpt.npz`) and the small npz reader/writer under it.
//!
//! svox2 layout: `links` int32 (X, Y, Z), `density_data` (n, 1) and `sh_data` (n, 27) in float16
//! or float32, `radius` and `center` float (3,). `basis_type`, when present, must be svox2's
//! spherical harmonics (1); other arrays (`background_data`, …) are ignored. A missing `radius`
//! is refused (svox2's loader would assume [1, 1, 1], which places the grid wrongly in any other
//! scene box); as in svox2, a missing `center` means [0, 0, 0]. Every float width (f2/f4/f8) is
//! read as f32. Negative links (svox2 stores skip distances
//! there after `accelerate()`) all mean empty and are normalised to −1 on import.
//! We export float32, entries stored uncompressed (np.load reads both stored and deflated ones).
//!
//! Every read is validated: dtype, shape, C order, entry size, CRC, link range and uniqueness,
//! finiteness; errors name the file and the array.

use std::fs::File;
use std::io::{self, BufReader, BufWriter, Read, Seek, Write};
use std::path::Path;

use anyhow::{bail, ensure, Context, Result};
use bytemuck::Pod;
use half::f16;
use npyz::{AutoSerialize, NpyFile, Order, WriterBuilder};
use zip::write::SimpleFileOptions;
use zip::{CompressionMethod, ZipArchive, ZipWriter};

use super::{Grid, SH_DIM};

/// Array data as read from an npz entry; every float width becomes f32.
#[derive(Debug, Clone, PartialEq)]
pub enum Data {
    F32(Vec<f32>),
    I32(Vec<i32>),
    U8(Vec<u8>),
}

impl Data {
    /// The dtype family, for error messages.
    pub fn kind(&self) -> &'static str {
        match self {
            Data::F32(_) => "float",
            Data::I32(_) => "int32",
            Data::U8(_) => "uint8",
        }
    }
}

/// One array: its shape and flat C-order data.
#[derive(Debug, Clone, PartialEq)]
pub struct Array {
    pub shape: Vec<u64>,
    pub data: Data,
}

/// Read access to the arrays of an `.npz` file.
pub struct NpzReader {
    zip: ZipArchive<BufReader<File>>,
}

impl NpzReader {
    /// Open `path` as a zip archive (errors say when it is not one, e.g. truncated).
    pub fn open(path: &Path) -> Result<Self> {
        let file = File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
        let zip = ZipArchive::new(BufReader::new(file)).with_context(|| {
            format!(
                "{} is not a readable npz (zip) archive: truncated or not an npz",
                path.display()
            )
        })?;
        Ok(NpzReader { zip })
    }

    /// Names of the arrays in the archive (entry names without `.npy`).
    pub fn names(&self) -> Vec<String> {
        self.zip
            .file_names()
            .filter_map(|n| n.ok())
            .filter_map(|n| n.strip_suffix(".npy").map(str::to_owned))
            .collect()
    }

    /// Whether the archive holds array `name`.
    pub fn contains(&self, name: &str) -> bool {
        self.zip.index_for_name(&format!("{name}.npy")).is_some()
    }

    /// Read array `name`; the error names the array (callers add the file).
    pub fn read(&mut self, name: &str) -> Result<Array> {
        if !self.contains(name) {
            bail!(
                "missing array '{name}' (arrays present: {})",
                self.names().join(", ")
            );
        }
        self.read_entry(name)
            .with_context(|| format!("array '{name}'"))
    }

    /// Float array `name` at double precision (float32 and float64 entries; IDR's camera
    /// matrices are float64 and need it): its shape and C-order values.
    pub fn read_f64(&mut self, name: &str) -> Result<(Vec<u64>, Vec<f64>)> {
        if !self.contains(name) {
            bail!(
                "missing array '{name}' (arrays present: {})",
                self.names().join(", ")
            );
        }
        let read = |zip: &mut ZipArchive<BufReader<File>>| -> Result<(Vec<u64>, Vec<f64>)> {
            read_npy_f64(BufReader::new(zip.by_name(&format!("{name}.npy"))?))
        };
        read(&mut self.zip).with_context(|| format!("array '{name}'"))
    }

    fn read_entry(&mut self, name: &str) -> Result<Array> {
        let entry = self.zip.by_name(&format!("{name}.npy"))?;
        let entry_size = entry.size();
        let mut r = BufReader::with_capacity(1 << 16, entry);
        let npy = NpyFile::new(&mut r).context("bad npy header")?;
        let shape = npy.shape().to_vec();
        let descr = npy.dtype().descr();
        ensure!(
            shape.len() < 2 || npy.order() == Order::C,
            "Fortran-ordered arrays are not supported (shape {shape:?})"
        );
        // Bound the element count by the entry's size before reading (no huge allocation).
        let count = shape.iter().try_fold(1u64, |a, &d| a.checked_mul(d));
        let item = npy.dtype().num_bytes().unwrap_or(0) as u64;
        let count = match count {
            Some(c) if c.checked_mul(item).is_some_and(|b| b <= entry_size) => c as usize,
            _ => bail!(
                "shape {shape:?} of {descr} needs more bytes than the entry's {entry_size} \
                 (truncated?)"
            ),
        };
        let data = decode(npy, count)?;
        // Read to the end: it verifies the zip CRC and catches trailing bytes.
        let rest = io::copy(&mut r, &mut io::sink()).context("entry corrupt (CRC/read error)")?;
        ensure!(rest == 0, "{rest} bytes after the data (shape {shape:?})");
        Ok(Array { shape, data })
    }
}

fn read_error(e: io::Error) -> anyhow::Error {
    match e.kind() {
        io::ErrorKind::UnexpectedEof => anyhow::anyhow!("data ends early (truncated?)"),
        _ => anyhow::Error::new(e).context("reading the data"),
    }
}

/// `count` native-endian values read straight into memory.
fn read_raw<T: Pod>(mut r: impl Read, count: usize) -> Result<Vec<T>> {
    let mut v = vec![T::zeroed(); count];
    r.read_exact(bytemuck::cast_slice_mut(&mut v))
        .map_err(read_error)?;
    Ok(v)
}

/// Decode the `count` values of an npy body into [`Data`]: native f32 / i32 by a raw copy, the
/// other supported dtypes element by element.
fn decode<R: Read>(npy: NpyFile<R>, count: usize) -> Result<Data> {
    fn all<T>(r: impl Iterator<Item = io::Result<T>>) -> Result<Vec<T>> {
        r.collect::<io::Result<_>>().map_err(read_error)
    }
    let dtype = npy.dtype();
    if dtype == f32::default_dtype() {
        return read_raw(npy.into_inner(), count).map(Data::F32);
    }
    if dtype == i32::default_dtype() {
        return read_raw(npy.into_inner(), count).map(Data::I32);
    }
    let descr = dtype.descr();
    let npy = match npy.try_data::<f32>() {
        Ok(r) => return all(r).map(Data::F32),
        Err(npy) => npy,
    };
    let npy = match npy.try_data::<f16>() {
        Ok(r) => return all(r.map(|v| v.map(f32::from))).map(Data::F32),
        Err(npy) => npy,
    };
    let npy = match npy.try_data::<f64>() {
        Ok(r) => return all(r.map(|v| v.map(|x| x as f32))).map(Data::F32),
        Err(npy) => npy,
    };
    let npy = match npy.try_data::<i32>() {
        Ok(r) => return all(r).map(Data::I32),
        Err(npy) => npy,
    };
    // numpy's default integer (svox2's `basis_type`), kept when it fits int32.
    let npy = match npy.try_data::<i64>() {
        Ok(r) => {
            let wide = all(r)?;
            let narrow: Option<Vec<i32>> = wide.iter().map(|&v| i32::try_from(v).ok()).collect();
            return narrow
                .map(Data::I32)
                .with_context(|| format!("int64 values beyond int32 ({descr})"));
        }
        Err(npy) => npy,
    };
    match npy.try_data::<u8>() {
        Ok(r) => all(r).map(Data::U8),
        Err(_) => bail!("unsupported dtype {descr} (expected float16/32/64, int32 or uint8)"),
    }
}

/// A small float `.npy` stream (float32 or float64, C order, at most 2²⁰ values: camera
/// matrices) at double precision: its shape and values.
pub fn read_npy_f64(reader: impl Read) -> Result<(Vec<u64>, Vec<f64>)> {
    let npy = NpyFile::new(reader).context("bad npy header")?;
    let shape = npy.shape().to_vec();
    ensure!(
        shape.len() < 2 || npy.order() == Order::C,
        "Fortran-ordered arrays are not supported (shape {shape:?})"
    );
    ensure!(
        shape.iter().product::<u64>() <= 1 << 20,
        "shape {shape:?} is too large for a camera matrix"
    );
    let descr = npy.dtype().descr();
    let values: io::Result<Vec<f64>> = match npy.try_data::<f64>() {
        Ok(r) => r.collect(),
        Err(npy) => match npy.try_data::<f32>() {
            Ok(r) => r.map(|v| v.map(f64::from)).collect(),
            Err(_) => bail!("dtype {descr}: expected float32 or float64"),
        },
    };
    Ok((shape, values.map_err(read_error)?))
}

/// A 1-D boolean mask `.npy` file (bool or uint8, nonzero = true), e.g. a capture's
/// `gt_points_visible.npy`.
pub fn read_mask(path: &Path) -> Result<Vec<bool>> {
    let read = || -> Result<Vec<bool>> {
        let npy = NpyFile::new(BufReader::new(File::open(path)?)).context("bad npy header")?;
        let shape = npy.shape().to_vec();
        ensure!(shape.len() == 1, "shape {shape:?}, expected one dimension");
        let descr = npy.dtype().descr();
        let values: io::Result<Vec<bool>> = match npy.try_data::<bool>() {
            Ok(r) => r.collect(),
            Err(npy) => match npy.try_data::<u8>() {
                Ok(r) => r.map(|v| v.map(|x| x != 0)).collect(),
                Err(_) => bail!("dtype {descr}: expected bool or uint8"),
            },
        };
        values.map_err(read_error)
    };
    read().with_context(|| format!("reading the mask {}", path.display()))
}

impl Array {
    /// The float data, or an error naming the actual dtype.
    pub fn into_f32(self, name: &str) -> Result<Vec<f32>> {
        match self.data {
            Data::F32(v) => Ok(v),
            d => bail!("array '{name}' has dtype {}, expected float", d.kind()),
        }
    }
}

/// Write access to a new `.npz` archive.
pub struct NpzWriter<W: Write + Seek> {
    zip: ZipWriter<W>,
}

impl<W: Write + Seek> NpzWriter<W> {
    /// Start an archive on `w`.
    pub fn new(w: W) -> Self {
        NpzWriter {
            zip: ZipWriter::new(w),
        }
    }

    /// Add array `name` of `shape` (C order, native endianness), stored uncompressed.
    pub fn array<T: AutoSerialize + Pod>(
        &mut self,
        name: &str,
        shape: &[u64],
        data: &[T],
    ) -> Result<()> {
        ensure!(
            shape.iter().product::<u64>() == data.len() as u64,
            "array '{name}': shape {shape:?} does not match {} values",
            data.len()
        );
        let bytes = std::mem::size_of_val(data) as u64;
        let options = SimpleFileOptions::default()
            .compression_method(CompressionMethod::Stored)
            .large_file(bytes >= u32::MAX as u64 - 4096);
        self.zip
            .start_file(format!("{name}.npy"), options)
            .with_context(|| format!("array '{name}'"))?;
        // npyz writes the header when the writer begins; the data goes in as raw native bytes
        // (the header's dtype is native-endian). Dropping the unfinished writer writes nothing.
        let mut header = Vec::new();
        drop(
            npyz::WriteOptions::<T>::new()
                .default_dtype()
                .shape(shape)
                .writer(&mut header)
                .begin_nd()?,
        );
        self.zip.write_all(&header)?;
        self.zip
            .write_all(bytemuck::cast_slice(data))
            .with_context(|| format!("writing array '{name}'"))?;
        Ok(())
    }

    /// Write the central directory; returns the underlying writer.
    pub fn finish(self) -> Result<W> {
        Ok(self.zip.finish()?)
    }
}

/// Write an npz atomically (see [`crate::io::atomic`]): on any error `path` is untouched, so a
/// crash mid-write leaves the previous file.
pub fn write_atomic(
    path: &Path,
    fill: impl FnOnce(&mut NpzWriter<&mut BufWriter<File>>) -> Result<()>,
) -> Result<()> {
    crate::io::atomic::write_atomic(path, |w| {
        let mut npz = NpzWriter::new(w);
        if let Err(e) = fill(&mut npz) {
            // Abandoned (its temporary is removed): a dropped zip writer would try to finalise
            // it and print its own raw error (a full disk) before the command's message.
            std::mem::forget(npz);
            return Err(e);
        }
        npz.finish()?.flush()?;
        Ok(())
    })
}

/// Finite-value, link-range and link-uniqueness checks on top of [`Grid::validate`].
pub fn check_grid(grid: &Grid) -> Result<()> {
    grid.validate().map_err(anyhow::Error::msg)?;
    let mut seen = vec![false; grid.allocated()];
    for (slot, &l) in grid.links.iter().enumerate() {
        if l >= 0 {
            ensure!(
                !std::mem::replace(&mut seen[l as usize], true),
                "links: row {l} is used by two vertices (second at {:?})",
                grid.vertex(slot)
            );
        }
    }
    for (name, v) in [("density_data", &grid.density), ("sh_data", &grid.sh)] {
        if let Some(i) = v.iter().position(|x| !x.is_finite()) {
            bail!("{name}: non-finite value {} at flat index {i}", v[i]);
        }
    }
    Ok(())
}

/// Read and validate the svox2 arrays of an open npz.
pub fn read_grid(npz: &mut NpzReader) -> Result<Grid> {
    let links = npz.read("links")?;
    let Data::I32(mut links_v) = links.data else {
        bail!(
            "array 'links' has dtype {}, expected int32",
            links.data.kind()
        );
    };
    ensure!(
        links.shape.len() == 3 && links.shape.iter().all(|&d| d <= u32::MAX as u64),
        "array 'links' has shape {:?}, expected (X, Y, Z)",
        links.shape
    );
    let res = [0, 1, 2].map(|i| links.shape[i] as u32);
    let density = npz.read("density_data")?;
    let n = density.shape.first().copied().unwrap_or(0);
    ensure!(
        density.shape == [n, 1],
        "array 'density_data' has shape {:?}, expected (n, 1)",
        density.shape
    );
    let density = density.into_f32("density_data")?;
    let sh = npz.read("sh_data")?;
    ensure!(
        sh.shape == [n, SH_DIM as u64],
        "array 'sh_data' has shape {:?}, expected ({n}, {SH_DIM}) (n from density_data; \
         SH degree 2 only)",
        sh.shape
    );
    let sh = sh.into_f32("sh_data")?;
    ensure!(
        npz.contains("radius"),
        "no array 'radius': the grid's extent in the scene is unknown (svox2 writes 'radius' and \
         'center' with every grid; add them, e.g. np.savez(..., radius=..., center=...))"
    );
    let mut vec3 = |name: &str, default: f32| -> Result<[f32; 3]> {
        if !npz.contains(name) {
            return Ok([default; 3]);
        }
        let a = npz.read(name)?;
        ensure!(
            a.shape == [3],
            "array '{name}' has shape {:?}, expected (3,)",
            a.shape
        );
        let v = a.into_f32(name)?;
        Ok([v[0], v[1], v[2]])
    };
    let radius = vec3("radius", 1.0)?;
    let center = vec3("center", 0.0)?;
    for l in &mut links_v {
        *l = (*l).max(-1);
    }
    let grid = Grid {
        res,
        center,
        radius,
        links: links_v,
        density,
        sh,
    };
    check_grid(&grid)?;
    Ok(grid)
}

/// Add the svox2 arrays of `grid` (float32) to an npz being written.
pub fn write_grid<W: Write + Seek>(npz: &mut NpzWriter<W>, grid: &Grid) -> Result<()> {
    check_grid(grid).context("refusing to write an invalid grid")?;
    let n = grid.allocated() as u64;
    npz.array("links", &grid.res.map(u64::from), &grid.links)?;
    npz.array("density_data", &[n, 1], &grid.density)?;
    npz.array("sh_data", &[n, SH_DIM as u64], &grid.sh)?;
    npz.array("radius", &[3], &grid.radius)?;
    npz.array("center", &[3], &grid.center)
}

/// svox2's `BASIS_TYPE_SH`: the only basis this crate renders.
const BASIS_TYPE_SH: i32 = 1;

/// Refuse an svox2 grid of another basis (3D texture 4, MLP 255): its `sh_data` is no SH.
fn check_basis(npz: &mut NpzReader) -> Result<()> {
    if !npz.contains("basis_type") {
        return Ok(());
    }
    let a = npz.read("basis_type")?;
    let v: Vec<f64> = match a.data {
        Data::I32(v) => v.into_iter().map(f64::from).collect(),
        Data::F32(v) => v.into_iter().map(f64::from).collect(),
        Data::U8(v) => v.into_iter().map(f64::from).collect(),
    };
    let shown: Vec<String> = v.iter().map(|x| x.to_string()).collect();
    ensure!(
        v == [BASIS_TYPE_SH as f64],
        "array 'basis_type' is [{}]: only spherical harmonics ({BASIS_TYPE_SH}, svox2's \
         BASIS_TYPE_SH) are supported, not a 3D texture (4) or an MLP (255) basis",
        shown.join(", ")
    );
    Ok(())
}

/// Import an svox2 `ckpt.npz`.
pub fn load_svox2(path: &Path) -> Result<Grid> {
    let mut npz = NpzReader::open(path)?;
    check_basis(&mut npz)
        .and_then(|()| read_grid(&mut npz))
        .with_context(|| format!("importing svox2 checkpoint {}", path.display()))
}

/// Export `grid` as an svox2 `ckpt.npz` (float32), written atomically.
pub fn save_svox2(grid: &Grid, path: &Path) -> Result<()> {
    write_atomic(path, |npz| write_grid(npz, grid))
}
