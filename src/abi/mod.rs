//! Types that cross the host/kernel boundary: what a kernel reads, in its buffers' layout, named
//! once for the Vulkan backend, the CPU twins and the owners of the data.

pub mod surface_grid;
