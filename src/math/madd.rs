//! `a·b + c` on the twins' decision paths (the DDA's cell estimate and correctly rounded 1/d and
//! |d|, the surface ray and a cell's entry/exit points, segment culling, the cubic solver's
//! bracket): two roundings by default, as lavapipe and `precise` GLSL evaluate it; one
//! (`f32::mul_add`) with the `fused` cargo feature, as a compiler that contracts a·b + c into an
//! FMA (NVIDIA's, where the GLSL allows it) would. `cargo test --features fused` runs the parity
//! tests with the twins contracted: their decisions must not depend on which (issue 21).

/// `a·b + c`, fused only with the `fused` feature.
#[inline(always)]
pub fn madd(a: f32, b: f32, c: f32) -> f32 {
    if cfg!(feature = "fused") {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}
