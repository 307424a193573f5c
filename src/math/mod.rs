//! Numerics shared by the CPU twins and the f64 oracles.

pub mod dda;
pub mod sh;
pub mod trilerp;
