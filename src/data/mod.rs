//! Datasets of posed images in five layouts ([`Layout`], detected from the files): NeRF-synthetic,
//! instant-ngp / nerfstudio, COLMAP, IDR/DTU and LLFF. Loading ([`Dataset::load`]), cameras and rays in the OpenGL convention
//! ([`Camera`]), the scene box ([`SceneBox`]), training views for ray sampling ([`TrainViews`])
//! and dataset inspection ([`inspect`]).

pub mod aabb;
pub mod background;
pub mod camera;
pub mod colmap;
pub mod dataset;
pub mod distortion;
pub mod error;
pub mod foreground;
pub mod idr;
pub mod image;
pub mod inspect;
pub mod instant_ngp;
pub mod layout;
pub mod llff;
mod load;
pub mod ndc;
mod nerf_synthetic;
pub mod sampler;
pub mod scene_box;
pub mod split;
mod transforms;
pub mod views;

pub use aabb::Aabb;
pub use background::BackgroundMode;
pub use camera::{look_at, Camera};
pub use dataset::{Dataset, LoadOptions, LoadReport};
pub use error::DataError;
pub use foreground::ForegroundBox;
pub use image::RgbaImage;
pub use layout::Layout;
pub use sampler::{view_rays, RayBatch, TrainViews};
pub use scene_box::SceneBox;
pub use split::{Frame, Split, SplitRule};
