//! Twin of `glsl/fill_pattern.comp`.

use rayon::prelude::*;

/// The kernel's hash, bit for bit.
pub fn hash_u32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

/// `dst[i] = hash(i ^ seed)` for every element.
pub fn fill_pattern(dst: &mut [u32], seed: u32) {
    dst.par_iter_mut()
        .enumerate()
        .for_each(|(i, v)| *v = hash_u32(i as u32 ^ seed));
}
