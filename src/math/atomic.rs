//! Float atomics for the CPU twins of scatter kernels: an `f32` slice viewed as `AtomicU32`s with
//! a compare-and-swap add and a max on non-negative floats (what the GPU kernels do).

use std::sync::atomic::{AtomicU32, Ordering};

/// View a float slice as atomics for a parallel scatter.
pub fn as_atomic(v: &mut [f32]) -> &[AtomicU32] {
    // SAFETY: AtomicU32 has the size and alignment of u32 (and f32); the exclusive borrow
    // guarantees no other access while the atomic view lives.
    unsafe { &*(v as *mut [f32] as *const [AtomicU32]) }
}

/// View a u32 slice as atomics.
pub fn as_atomic_u32(v: &mut [u32]) -> &[AtomicU32] {
    // SAFETY: as for `as_atomic`.
    unsafe { &*(v as *mut [u32] as *const [AtomicU32]) }
}

/// `*a += v` atomically.
pub fn add(a: &AtomicU32, v: f32) {
    let _ = a.fetch_update(Ordering::Relaxed, Ordering::Relaxed, |bits| {
        Some((f32::from_bits(bits) + v).to_bits())
    });
}

/// `*a = max(*a, v)` atomically, for non-negative floats (their bit patterns order like them).
pub fn max_nonneg(a: &AtomicU32, v: f32) {
    a.fetch_max(v.to_bits(), Ordering::Relaxed);
}
