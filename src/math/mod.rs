//! Numerics shared by the CPU twins and the f64 oracles: the Rust twins of `glsl/lib/`; and the
//! geometry the data and the evaluation share: nearest neighbours in a point cloud ([`knn`]) and
//! percentile boxes of points ([`percentile`]).

// These twins of `glsl/lib/` mirror its loops index for index; iterator rewrites would hide that.
// `!(a < b)` is deliberate where NaN must take the same branch as on the GPU.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

pub mod atomic;
pub mod background_msi;
pub mod cubic;
pub mod cubic_oracle;
pub mod dda;
pub mod knn;
pub mod madd;
pub mod ndc;
pub mod percentile;
pub mod plenoxel;
pub mod rmsprop;
pub mod sh;
pub mod step;
pub mod surface;
pub mod surface_blocks;
pub mod surface_train;
pub mod surface_walk;
pub mod trilerp;
pub mod vieta;
