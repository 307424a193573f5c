//! Integration tests of the pipeline as a library, one binary: dataset loaders and their errors,
//! PLY files, the built-in scenes, checkpoints and svox2 import/export, extraction and
//! evaluation, and the training backends against each other.

#[path = "../common/data_common.rs"]
mod data_common;

mod checkpoint;
mod data_capture;
mod data_errors;
mod data_fixture;
mod data_instant_ngp;
mod data_loader;
mod data_ply;
mod eval;
mod render_samples;
mod scene_generate;
mod scene_shapes;
mod surface_train_gpu;
