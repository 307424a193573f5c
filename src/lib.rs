//! alphasurf — αSurf surface reconstruction on Vulkan compute (ash + gpu-allocator), with a CPU
//! twin for every kernel. See README.md.

pub mod abi;
pub mod backend;
pub mod bench;
pub mod check;
pub mod checkpoint;
pub mod cli;
pub mod cpu;
pub mod data;
pub mod eval;
pub mod gpu;
pub mod grid;
pub mod io;
pub mod kernels;
pub mod math;
pub mod mesh;
pub mod pipeline;
pub mod plenoxel;
pub mod report;
pub mod run;
pub mod scene;
pub mod stage;
pub mod surface;
pub mod train;
