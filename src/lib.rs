//! alphasurf — αSurf surface reconstruction on Vulkan compute (ash + gpu-allocator), with a CPU
//! twin for every kernel. See README.md.

pub mod bench;
pub mod check;
pub mod cli;
pub mod cpu;
pub mod gpu;
pub mod kernels;
pub mod math;
