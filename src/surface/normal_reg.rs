//! Recording of the stage-2 normal regularisers Ln1 + Ln2 (method.md §3.4) on the Vulkan device:
//! the three passes `surface_normal_reg_{cells,pairs,gather}` (definition in
//! `glsl/surface_normal_reg_pairs.comp`, layouts in `glsl/lib/normal_reg.glsl`, twin
//! `cpu::surface_reg::normal_reg_passes`), shared by `VulkanSurface` and the parity checks.

use crate::abi::normal_reg::{NormalChunk, NormalPrefix, CORNERS_STRIDE, NORMALS_STRIDE};
use crate::gpu::{Batch, Gpu, GpuBuffer};
use crate::kernels;
use anyhow::{ensure, Result};

/// The per-grid buffers of the passes: the neighbour table and the work lists (static), and the
/// per-row arrays they pass on.
pub struct NormalRegBuffers {
    pub nbr: GpuBuffer,
    pub cell_rows: GpuBuffer,
    pub corner_rows: GpuBuffer,
    /// Counts of the work lists.
    pub n_cells: u32,
    pub n_corners: u32,
    /// (n, status + 4·k) per row: 0 from the start, the rows of the existing cells rewritten
    /// by every run.
    pub normals: GpuBuffer,
    /// ∂L/∂δ of the 8 corners of each row's cell: +∞ (no pair) from the start, the rows of the
    /// existing cells rewritten by every run.
    pub corners: GpuBuffer,
}

impl NormalRegBuffers {
    /// The buffers of the grid of `prefix`.
    pub fn new(gpu: &Gpu, prefix: &NormalPrefix) -> Result<Self> {
        let rows = (prefix.rows() as usize).max(1);
        let b = NormalRegBuffers {
            nbr: gpu.upload_nonempty(prefix.neighbours())?,
            cell_rows: gpu.upload_nonempty(prefix.cell_rows())?,
            corner_rows: gpu.upload_nonempty(prefix.corner_rows())?,
            n_cells: prefix.cell_rows().len() as u32,
            n_corners: prefix.corner_rows().len() as u32,
            normals: gpu.zeros::<f32>(NORMALS_STRIDE * rows)?,
            corners: gpu.upload(&vec![f32::INFINITY; CORNERS_STRIDE * rows])?,
        };
        // The kernels read them as 64-bit words and pairs of words, declared 16-byte aligned.
        for buf in [&b.nbr, &b.normals, &b.corners] {
            ensure!(
                buf.address() % 16 == 0,
                "normal regulariser buffer at {:#x} is not 16-byte aligned",
                buf.address()
            );
        }
        Ok(b)
    }
}

/// Device addresses of the inputs and outputs of the passes.
#[derive(Clone, Copy, Debug)]
pub struct NormalRegIo {
    pub delta: u64,
    /// ∂/∂δ, added to.
    pub grad: u64,
    /// The step record (touched flags and list).
    pub step: u64,
    /// One float, added to.
    pub loss: u64,
    /// One u32, added to (pairs skipped for a tiny normal).
    pub skipped: u64,
}

/// Record the three passes for chunk `c` of the grid of `bufs` (nothing for an empty chunk or a
/// grid without cells). The cells and pairs passes run over the cells of the chunk's window, the
/// gather over their corners (`NormalChunk::cells_work`, `corners_work`): the pairs pass gathers
/// the pairs of the chunk's cells from both of their cells.
pub fn record_normal_reg(
    b: &mut Batch,
    bufs: &NormalRegBuffers,
    io: &NormalRegIo,
    c: &NormalChunk,
) -> Result<()> {
    let rows = c.rows;
    if c.count.min(rows) == 0 || bufs.n_cells == 0 {
        return Ok(());
    }
    b.dispatch_1d(
        &kernels::surface_normal_reg_cells::INFO,
        &kernels::surface_normal_reg_cells::Push {
            cell_rows: bufs.cell_rows.address(),
            nbr: bufs.nbr.address(),
            delta: io.delta,
            normals: bufs.normals.address(),
            n_cells: bufs.n_cells,
            first: c.cells_work.0,
            work: c.cells_work.1,
            ..Default::default()
        },
        c.cells_work.1,
    )?;
    b.dispatch_1d(
        &kernels::surface_normal_reg_pairs::INFO,
        &kernels::surface_normal_reg_pairs::Push {
            cell_rows: bufs.cell_rows.address(),
            nbr: bufs.nbr.address(),
            normals: bufs.normals.address(),
            corners: bufs.corners.address(),
            loss: io.loss,
            skipped: io.skipped,
            n_cells: bufs.n_cells,
            first: c.cells_work.0,
            work: c.cells_work.1,
            rows,
            start: c.start % rows,
            count: c.count.min(rows),
            cells: c.cells,
            lambda1: c.lambda1,
            lambda2: c.lambda2,
            ..Default::default()
        },
        c.cells_work.1,
    )?;
    b.dispatch_1d(
        &kernels::surface_normal_reg_gather::INFO,
        &kernels::surface_normal_reg_gather::Push {
            corner_rows: bufs.corner_rows.address(),
            nbr: bufs.nbr.address(),
            corners: bufs.corners.address(),
            grad: io.grad,
            step: io.step,
            n_corners: bufs.n_corners,
            first: c.corners_work.0,
            work: c.corners_work.1,
            rows,
            start: c.start % rows,
            window: c.window,
            touch_bits: c.touch,
            ..Default::default()
        },
        c.corners_work.1,
    )
}
