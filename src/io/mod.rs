//! File formats shared by the data, extraction and evaluation code: PLY point clouds.

pub mod ply;

pub use ply::{read_ply, read_points, write_ply, write_points, Extra, ExtraValues, PointCloud};
