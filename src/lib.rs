//! alphasurf — αSurf surface reconstruction on Vulkan compute (ash + gpu-allocator), with a CPU
//! twin for every kernel. See README.md.

// The CPU twins mirror GLSL loops index for index; iterator rewrites would hide that.
// `!(a < b)` is deliberate where NaN must take the same branch as on the GPU.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

pub mod bench;
pub mod check;
pub mod cli;
pub mod cpu;
pub mod data;
pub mod eval;
pub mod gpu;
pub mod grid;
pub mod io;
pub mod kernels;
pub mod math;
pub mod plenoxel;
pub mod report;
pub mod scene;
pub mod surface;
pub mod train;
