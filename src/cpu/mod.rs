//! CPU twins of the GLSL kernels: one function per kernel, same inputs and outputs, same
//! formulation, run with rayon. They validate the GPU kernels and serve as the CPU backend.

pub mod atomic;
mod fill_pattern;
pub mod plenoxel;
mod rmsprop;
mod tv;

pub use fill_pattern::fill_pattern;
pub use rmsprop::rmsprop;
pub use tv::{tv, TvChunk};
