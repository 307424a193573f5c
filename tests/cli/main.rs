//! Integration tests that drive the `alphasurf` command line end to end, one binary: data
//! commands, training of both stages, render, export, extract (points and mesh), eval, the
//! benchmarks' `--json`, the demo, and the safety of user files.

mod bench_common;
#[path = "../common/data_common.rs"]
mod data_common;

mod bench_accuracy;
mod data_cli;
mod demo_cli;
mod mesh_cli;
mod ndc_cli;
mod probe_cli;
mod safety_cli;
mod surface_cli;
mod train_cli;
