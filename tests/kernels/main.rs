//! Integration tests of the kernels and their numerics, one binary: every parity row against its
//! CPU twin, the backward passes against finite differences, the cubic solver, the DDA walk,
//! trilinear interpolation and SH, the SPIR-V contraction audit and the Vulkan runtime.
//! Select a module or a test by path, e.g. `cargo test --test kernels parity::surface_fwd`.

mod cubic;
mod dda;
mod gpu_runtime;
mod parity;
mod plenoxel_grad;
mod spirv_contraction;
mod surface_fwd;
mod surface_grad;
mod surface_reg;
mod trilerp_sh;
