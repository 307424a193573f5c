//! Numerics shared by the CPU twins and the f64 oracles: the Rust twins of `glsl/lib/`.

pub mod dda;
pub mod plenoxel;
pub mod sh;
pub mod trilerp;
