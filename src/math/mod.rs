//! Numerics shared by the CPU twins and the f64 oracles: the Rust twins of `glsl/lib/`.

pub mod cubic;
pub mod cubic_oracle;
pub mod dda;
pub mod plenoxel;
pub mod sh;
pub mod surface;
pub mod surface_blocks;
pub mod trilerp;
pub mod vieta;
