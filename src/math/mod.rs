//! Numerics shared by the CPU twins and the f64 oracles.

pub mod cubic;
pub mod cubic_oracle;
pub mod vieta;
