//! CPU twins of the GLSL kernels: one function per kernel, same inputs and outputs, same
//! formulation, run with rayon. They validate the GPU kernels and serve as the CPU backend.

// The CPU twins mirror GLSL loops index for index; iterator rewrites would hide that.
// `!(a < b)` is deliberate where NaN must take the same branch as on the GPU.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

pub mod atomic;
pub mod background;
pub mod cubic_solve;
mod dda_walk;
pub mod extract_points;
mod fill_pattern;
mod loss_sum;
pub mod plenoxel;
mod rmsprop;
pub mod sample_rays;
mod sh_eval;
pub mod step;
pub mod surface_blocks;
pub mod surface_delta_tv;
pub mod surface_fwd;
pub mod surface_reg;
pub mod surface_train;
mod trilerp_eval;
mod tv;

pub use dda_walk::dda_walk;
pub use fill_pattern::fill_pattern;
pub use loss_sum::loss_sum;
pub use rmsprop::{
    rmsprop_one, rmsprop_sparse, surface_rmsprop_sparse, RmsProp, Stage1Params, Stage2Params,
    SurfaceRmsProp,
};
pub use sh_eval::sh_eval;
pub use trilerp_eval::trilerp_eval;
pub use tv::{tv, TvChunk};
