//! Backend-agnostic training: configurations and presets, learning-rate schedules, the stage-1
//! loop with checkpoints, progress, rendering and metrics.

pub mod background;
pub mod config;
pub mod preset;
pub mod progress;
pub mod render;
pub mod schedule;
pub mod stage1;
pub mod stage2;
pub mod surface_config;

pub use background::BackgroundRecord;
pub use config::Stage1Config;
pub use preset::{Category, Preset};
pub use render::{psnr, render_split, render_split_with, RenderedSplit, MAX_PIXEL_SAMPLES};
pub use schedule::DelayedExp;
pub use surface_config::SurfaceConfig;
