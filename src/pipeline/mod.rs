//! The pipeline as a library: each command's work as a function taking its typed options (the
//! same structs are the command-line flags) and returning what it measured, for the CLI to print
//! and for `demo` and the benchmarks to call directly. Train ([`train::train`],
//! [`train_plenoxels::train_plenoxels`], [`train_surface::train_surface`]), [`extract::extract`],
//! [`evaluate::evaluate`], [`render::render`], svox2 [`svox2::export`] / [`svox2::import`], and
//! [`demo::demo`]; a run's `metrics.json` typed in [`metrics`]; the device of a command in
//! [`device`]; the demo's and benchmarks' steps in [`steps`].

pub mod demo;
pub mod device;
pub mod evaluate;
pub mod extract;
pub mod metrics;
pub mod render;
pub mod steps;
pub mod svox2;
pub mod train;
pub mod train_options;
pub mod train_plenoxels;
pub mod train_run;
pub mod train_surface;

pub use device::Devices;
pub use metrics::{PlenoxelsMetrics, SurfaceMetrics};
pub use train_options::{Stage, TrainOptions};
