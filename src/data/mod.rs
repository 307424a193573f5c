//! Datasets in the NeRF-synthetic format: loading ([`Dataset::load`]), cameras and rays in the
//! OpenGL convention ([`Camera`]), the scene box ([`SceneBox`]), ray batch sampling
//! ([`RaySampler`]) and dataset inspection ([`inspect`]).

pub mod camera;
pub mod dataset;
pub mod error;
pub mod image;
pub mod inspect;
pub mod sampler;

pub use camera::{look_at, Camera, SceneBox};
pub use dataset::{Dataset, Frame, LoadOptions, LoadReport, Split};
pub use error::DataError;
pub use image::RgbaImage;
pub use sampler::{view_rays, PixelRef, RayBatch, RaySampler};
