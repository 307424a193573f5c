//! Which dataset layout a directory holds, decided from the files present, in a fixed order:
//! NeRF-synthetic (any `transforms_{train,val,test}.json`), instant-ngp / nerfstudio (one
//! `transforms.json`), IDR/DTU (`cameras_sphere.npz`), COLMAP (`sparse/0/` or `sparse/` with
//! `cameras.bin` or `cameras.txt`; binary wins when both exist), LLFF (`poses_bounds.npy`; a
//! COLMAP model beside it wins: it has the sparse points).

use super::error::DataError;
use std::path::{Path, PathBuf};

/// A dataset layout on disk.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Layout {
    /// `transforms_{train,val,test}.json` with images (Blender).
    NerfSynthetic,
    /// One `transforms.json` with images (instant-ngp / nerfstudio).
    InstantNgp,
    /// A COLMAP reconstruction: `images/` and a sparse model.
    Colmap {
        /// The model folder (`sparse/0` or `sparse`).
        sparse: PathBuf,
        /// Whether the model is read from `*.bin` (else `*.txt`).
        binary: bool,
    },
    /// The IDR layout used for DTU: `cameras_sphere.npz`, `image/`, optional `mask/`.
    Idr,
    /// LLFF: `poses_bounds.npy` and `images/` (`images_4/8`).
    Llff,
}

impl std::fmt::Display for Layout {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Layout::NerfSynthetic => f.write_str("NeRF-synthetic (transforms_*.json)"),
            Layout::InstantNgp => f.write_str("instant-ngp / nerfstudio (transforms.json)"),
            Layout::Colmap { sparse, binary } => write!(
                f,
                "COLMAP ({}, {})",
                sparse.display(),
                if *binary { "binary" } else { "text" }
            ),
            Layout::Idr => f.write_str("IDR/DTU (cameras_sphere.npz)"),
            Layout::Llff => f.write_str("LLFF (poses_bounds.npy)"),
        }
    }
}

/// The layout of dataset directory `root`.
pub fn detect(root: &Path) -> Result<Layout, DataError> {
    let transforms = |s: &str| root.join(format!("transforms_{s}.json")).exists();
    if ["train", "val", "test"].into_iter().any(transforms) {
        return Ok(Layout::NerfSynthetic);
    }
    if root.join(super::instant_ngp::FILE).is_file() {
        return Ok(Layout::InstantNgp);
    }
    if root.join("cameras_sphere.npz").exists() {
        return Ok(Layout::Idr);
    }
    for sparse in [root.join("sparse").join("0"), root.join("sparse")] {
        for binary in [true, false] {
            let ext = if binary { "bin" } else { "txt" };
            if sparse.join(format!("cameras.{ext}")).is_file() {
                return Ok(Layout::Colmap { sparse, binary });
            }
        }
    }
    if root.join(super::llff::FILE).is_file() {
        return Ok(Layout::Llff);
    }
    Err(DataError::UnknownLayout {
        path: root.to_path_buf(),
    })
}
