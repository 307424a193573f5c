//! Types that cross the host/kernel boundary: what a kernel reads, in its buffers' layout, named
//! once for the Vulkan backend, the CPU twins and the owners of the data. `consts` and `buffers`
//! are also read by `build.rs`, which generates the kernels' declarations from them (`abi.glsl`).

#[macro_use]
mod macros;
pub mod background;
pub mod buffers;
pub mod consts;
pub mod extract;
pub mod normal_reg;
pub mod rays;
pub mod regularisers;
pub mod step;
pub mod surface_grid;
pub mod train;
