//! File formats shared by the data, extraction and evaluation code: PLY point clouds, and the
//! atomic writes every output goes through.

pub mod atomic;
pub mod ply;

pub use ply::{read_ply, read_points, write_ply, write_points, Extra, ExtraValues, PointCloud};
