//! File formats shared by the data, extraction and evaluation code: PLY point clouds, the atomic
//! writes every output goes through, and checkpoints written in the background.

pub mod atomic;
pub mod background_save;
pub mod ply;

pub use ply::{read_ply, read_points, write_ply, write_points, Extra, ExtraValues, PointCloud};
