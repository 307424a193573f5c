//! Backend-agnostic training: configurations and presets, learning-rate schedules, the training
//! loop of both stages ([`steps`]) and what each stage adds to it ([`plenoxels_steps`], [`surface_steps`]),
//! progress and the test renders.

pub mod config;
pub mod plenoxels_steps;
pub mod preset;
pub mod progress;
pub mod render;
pub mod schedule;
pub mod steps;
pub mod surface_config;
pub mod surface_steps;

pub use config::PlenoxelsConfig;
pub use preset::{Category, Preset};
pub use render::{render_split, render_split_with, RenderedSplit, MAX_PIXEL_SAMPLES};
pub use schedule::DelayedExp;
pub use surface_config::SurfaceConfig;
