//! Benchmarks behind `alphasurf bench …`: they print figures (and a JSON line with --json).

pub mod accuracy;
pub mod cubic;
pub mod dda;
pub mod plenoxels;
mod stage1;
pub mod surface;
pub mod time_vs_error;
