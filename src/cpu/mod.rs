//! CPU twins of the GLSL kernels: one function per kernel, same inputs and outputs, same
//! formulation, run with rayon. They validate the GPU kernels and serve as the CPU backend.

pub mod cubic_solve;
mod fill_pattern;
pub use fill_pattern::fill_pattern;
