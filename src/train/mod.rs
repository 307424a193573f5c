//! Backend-agnostic training: configurations and presets, learning-rate schedules, the stage-1
//! loop with checkpoints, progress, rendering and metrics.

pub mod config;
pub mod progress;
pub mod render;
pub mod schedule;
pub mod stage1;

pub use config::Stage1Config;
pub use render::{psnr, render_split, RenderedSplit};
pub use schedule::DelayedExp;
