//! Recording of Lδ (method.md §3.4) on the Vulkan device: the two stages of
//! `surface_delta_tv` over a [`DeltaTvChunk`] (twin `cpu::surface_delta_tv`), shared by
//! `VulkanSurface` and the parity checks.

use crate::abi::regularisers::DeltaTvChunk;
use crate::gpu::Batch;
use crate::kernels;
use anyhow::{ensure, Result};

pub use crate::abi::consts::Q_FLOATS;

/// Device addresses of the inputs and outputs of the passes.
#[derive(Clone, Copy, Debug)]
pub struct DeltaTvIo {
    /// The axis-neighbour table (`axis_neighbours`).
    pub nbr: u64,
    pub delta: u64,
    /// Per-row directions, [`Q_FLOATS`] floats per row (scratch).
    pub q: u64,
    /// ∂/∂δ, added to.
    pub grad: u64,
}

/// Record both stages for chunk `c` (`reach`: the table's `forward_reach`): stage 0 over the
/// chunk's rows, stage 1 over its window.
pub fn record_delta_tv(b: &mut Batch, io: &DeltaTvIo, c: &DeltaTvChunk, reach: u32) -> Result<()> {
    ensure!(
        c.rows > 0 && c.start < c.rows && c.count <= c.rows,
        "Lδ chunk of {} rows from {} on a grid of {} rows",
        c.count,
        c.start,
        c.rows
    );
    let window = c.window(reach).len;
    for (stage, n) in [(0, c.count), (1, window)] {
        b.dispatch_1d(
            &kernels::surface_delta_tv::INFO,
            &kernels::surface_delta_tv::Push {
                nbr: io.nbr,
                delta: io.delta,
                q: io.q,
                grad: io.grad,
                rows: c.rows,
                stage,
                start: c.start,
                count: c.count,
                window,
                scale: c.scale,
            },
            n,
        )?;
    }
    Ok(())
}
