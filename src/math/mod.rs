//! Numerics shared by the CPU twins and the f64 oracles.
