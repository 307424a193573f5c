//! Backend-agnostic training: configurations and presets, learning-rate schedules, the training
//! loop of both stages ([`steps`]) and what each stage adds to it ([`stage1`], [`stage2`]),
//! progress and the test renders.

pub mod config;
pub mod preset;
pub mod progress;
pub mod render;
pub mod schedule;
pub mod stage1;
pub mod stage2;
pub mod steps;
pub mod surface_config;

pub use config::Stage1Config;
pub use preset::{Category, Preset};
pub use render::{render_split, render_split_with, RenderedSplit, MAX_PIXEL_SAMPLES};
pub use schedule::DelayedExp;
pub use surface_config::SurfaceConfig;
