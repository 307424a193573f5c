//! A sparse grid on the device as both stages' Vulkan backends hold it: its links and, per
//! optimised array (stage 1: σ, SH; stage 2: δ, σα, SH), the values, their gradient and their
//! RMSProp running average, each array `rows` vertex rows of a fixed number of floats.

use super::{Gpu, GpuBuffer, SlotFigures, StepQueue};
use crate::grid::state_bytes;
use anyhow::{ensure, Result};

/// A grid's links and optimised arrays on the device.
pub struct GridBuffers {
    /// One i32 per vertex slot: the vertex's row, < 0 where none is allocated.
    pub links: GpuBuffer,
    /// Per array, in the order the backend names them: the values, dL/d(value) accumulated by
    /// the step's passes, and the running average of the squared gradient.
    pub values: Vec<GpuBuffer>,
    pub grads: Vec<GpuBuffer>,
    pub states: Vec<GpuBuffer>,
    /// Vertex slots (links).
    slots: usize,
    /// Allocated vertex rows.
    rows: usize,
    /// Floats per array.
    lens: Vec<usize>,
}

impl GridBuffers {
    /// `links` and the `arrays` of `rows` vertex rows on `gpu`, with zero gradients and running
    /// averages (an empty array takes one zero float: kernels bind every buffer).
    pub fn new(gpu: &Gpu, links: &[i32], rows: usize, arrays: &[&[f32]]) -> Result<Self> {
        let lens: Vec<usize> = arrays.iter().map(|a| a.len()).collect();
        let zeros = || -> Result<Vec<GpuBuffer>> {
            lens.iter().map(|&n| gpu.zeros::<f32>(n.max(1))).collect()
        };
        Ok(GridBuffers {
            links: gpu.upload(links)?,
            values: arrays
                .iter()
                .map(|a| gpu.upload_nonempty(a))
                .collect::<Result<_>>()?,
            grads: zeros()?,
            states: zeros()?,
            slots: links.len(),
            rows,
            lens,
        })
    }

    /// Allocated vertex rows.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// The links, downloaded.
    pub fn download_links(&self) -> Result<Vec<i32>> {
        self.links.download_range(0, self.slots)
    }

    /// Every array's values, downloaded.
    pub fn download_values(&self) -> Result<Vec<Vec<f32>>> {
        self.download_each(&self.values)
    }

    /// Every array's running averages, downloaded.
    pub fn download_states(&self) -> Result<Vec<Vec<f32>>> {
        self.download_each(&self.states)
    }

    /// Every array's gradient, downloaded, then the gradients and the touched flags of the
    /// queue's step record cleared, so that none stays behind for the next step.
    pub fn take_grads<F: SlotFigures>(&self, queue: &StepQueue<F>) -> Result<Vec<Vec<f32>>> {
        let grads = self.download_each(&self.grads)?;
        let bufs: Vec<&GpuBuffer> = self.grads.iter().collect();
        queue.clear_gradients(&bufs, self.rows)?;
        Ok(grads)
    }

    /// Write the running averages (`states`, one per array, each of the array's length).
    pub fn write_states(&self, states: &[&[f32]]) -> Result<()> {
        let lens: Vec<usize> = states.iter().map(|s| s.len()).collect();
        ensure!(
            lens == self.lens,
            "optimizer state of {lens:?} floats does not match the grid's {:?}",
            self.lens
        );
        for (buf, s) in self.states.iter().zip(states) {
            buf.write(s)?;
        }
        Ok(())
    }

    /// Bytes of a copy of the links, the values and the running averages (what a checkpoint
    /// holds).
    pub fn state_bytes(&self) -> u64 {
        let floats: usize = self.lens.iter().sum();
        let per_row = floats / self.rows.max(1);
        state_bytes(self.slots as u64, self.rows as u64, per_row as u64)
    }

    fn download_each(&self, bufs: &[GpuBuffer]) -> Result<Vec<Vec<f32>>> {
        bufs.iter()
            .zip(&self.lens)
            .map(|(b, &n)| b.download_range(0, n))
            .collect()
    }
}
