//! CPU twins of the GLSL kernels: one function per kernel, same inputs and outputs, same
//! formulation, run with rayon. They validate the GPU kernels and serve as the CPU backend.

// The CPU twins mirror GLSL loops index for index; iterator rewrites would hide that.
// `!(a < b)` is deliberate where NaN must take the same branch as on the GPU.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

mod background_msi_eval;
pub mod background_spheres_step;
pub mod background_step;
pub mod cubic_solve;
mod dda_walk;
pub mod extract_points;
mod fill_pattern;
mod loss_sum;
pub mod occupancy;
pub mod optim_args;
pub mod plenoxel_fwd;
pub mod plenoxel_train;
pub mod plenoxel_weights;
mod rmsprop_sparse;
pub mod sample_rays;
mod sh_eval;
pub mod surface_blocks;
pub mod surface_delta_tv;
pub mod surface_fwd;
pub mod surface_live_cells;
pub mod surface_normal_reg_cells;
pub mod surface_normal_reg_gather;
pub mod surface_normal_reg_pairs;
pub mod surface_opacity_reg;
pub mod surface_reg;
mod surface_rmsprop;
pub mod surface_train;
mod trilerp_eval;
mod tv;

pub use background_msi_eval::background_msi_eval;
pub use dda_walk::dda_walk;
pub use fill_pattern::fill_pattern;
pub use loss_sum::loss_sum;
pub use rmsprop_sparse::{rmsprop_sparse, PlenoxelsOptimArrays};
pub use sh_eval::sh_eval;
pub use surface_rmsprop::{surface_rmsprop, SurfaceOptimArrays};
pub use trilerp_eval::trilerp_eval;
pub use tv::tv;

/// Twin of `glsl/sample_rays_sort.comp`: the host's sort of a batch's keys in runs, which the
/// host draw of the keys (`abi::rays::sorted_keys`) shares (any sort of a run gives the kernel's
/// bitonic order).
pub use crate::abi::rays::sample_rays_sort;
/// Twin of `glsl/surface_block_radius.comp`: its three passes, `surf_block_radii` in
/// `math::surface_blocks` with the skip structure's other conventions (and its tests).
pub use crate::math::surface_blocks::surf_block_radii as surface_block_radius;
