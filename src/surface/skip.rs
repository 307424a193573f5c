//! Recording of the stage-2 walks' skip structure on the device (glsl/lib/surface_blocks.glsl):
//! `surface_live_cells` writes the live-cell words, `surface_blocks` the block masks after them,
//! and three passes of `surface_block_radius` add the empty radii of the mask-0 blocks.
//! Shared by `VulkanSurface` and the parity check; CPU twin: `cpu::surface_blocks::build_blocks`.

use crate::gpu::Batch;
use crate::kernels;
use crate::math::surface_blocks::{surf_blocks_per_axis, surf_live_words};
use anyhow::Result;

/// Device addresses and sizes the two kernels read and write.
pub struct SkipIo {
    /// Static complete-cell bits (`math::surface_blocks::complete_cells`).
    pub complete: u64,
    pub links: u64,
    pub delta: u64,
    /// 8 floats, zero-padded.
    pub levels: u64,
    /// Output: `surf_live_words(n)` live-cell words, then the nb³ block words (masks and radii).
    pub skip: u64,
    /// 2·nb³ u32 of scratch for the radius passes.
    pub scratch: u64,
    pub n: u32,
    pub n_levels: u32,
    /// log2 of the block edge in cells.
    pub shift: u32,
}

/// Record the kernels for δ ranges widened by `margin`.
pub fn record_skip_structure(b: &mut Batch, io: &SkipIo, margin: f32) -> Result<()> {
    let words = surf_live_words(io.n);
    let nb = surf_blocks_per_axis(io.n, io.shift);
    b.dispatch_1d(
        &kernels::surface_live_cells::INFO,
        &kernels::surface_live_cells::Push {
            complete: io.complete,
            links: io.links,
            delta: io.delta,
            levels: io.levels,
            live: io.skip,
            n: io.n,
            n_levels: io.n_levels,
            margin,
            ..Default::default()
        },
        words,
    )?;
    b.dispatch_1d(
        &kernels::surface_blocks::INFO,
        &kernels::surface_blocks::Push {
            links: io.links,
            delta: io.delta,
            levels: io.levels,
            blocks: io.skip + 4 * words as u64,
            n: io.n,
            n_levels: io.n_levels,
            margin,
            block_shift: io.shift,
        },
        nb * nb * nb,
    )?;
    for pass in 0..3 {
        b.dispatch_1d(
            &kernels::surface_block_radius::INFO,
            &kernels::surface_block_radius::Push {
                blocks: io.skip + 4 * words as u64,
                scratch: io.scratch,
                nb,
                pass,
            },
            nb * nb * nb,
        )?;
    }
    Ok(())
}
