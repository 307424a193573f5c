//! Per-step results brought back without a submission of their own: the step's batch ends with
//! copies of the device ranges into one host-visible buffer, read after the batch's fence wait.
//! (Reading a device buffer directly costs a staging buffer and a submission where device memory
//! is not host-visible, as on a discrete GPU.)

use super::{Batch, Gpu, GpuBuffer};
use anyhow::{ensure, Result};
use bytemuck::Pod;

/// A host-visible buffer that a batch's copies fill, in parts.
#[derive(Default)]
pub struct Readback {
    buf: Option<GpuBuffer>,
    /// (offset, bytes) of each part of the last recording.
    parts: Vec<(u64, u64)>,
}

impl Readback {
    /// Records, at this point of `b`, copies of `parts` — (buffer, byte offset, bytes) — one after
    /// the other into the host-visible buffer (grown to the next power of two when they do not
    /// fit; the device must be done with the old one, as it is between steps).
    pub fn record(
        &mut self,
        gpu: &Gpu,
        b: &mut Batch,
        parts: &[(&GpuBuffer, u64, u64)],
    ) -> Result<()> {
        // Parts start on 16-byte boundaries (the copies' offsets need 4).
        let mut at = 0;
        self.parts = parts
            .iter()
            .map(|&(_, _, bytes)| {
                let part = (at, bytes);
                at += bytes.next_multiple_of(16);
                part
            })
            .collect();
        if self.buf.as_ref().is_none_or(|r| r.size() < at) {
            let words = (at / 4).max(4).next_power_of_two() as usize;
            self.buf = Some(gpu.device_to_host::<u32>(words)?);
        }
        let dst = self.buf.as_ref().expect("just set");
        for (&(src, offset, bytes), &(to, _)) in parts.iter().zip(&self.parts) {
            b.copy_region(src, offset, dst, to, bytes);
        }
        Ok(())
    }

    /// Part `i` of the last recording as `T`s (once its batch has been submitted and waited on).
    pub fn part<T: Pod>(&self, i: usize) -> Result<Vec<T>> {
        ensure!(i < self.parts.len(), "readback part {i} was not recorded");
        let (offset, bytes) = self.parts[i];
        let elem = std::mem::size_of::<T>() as u64;
        ensure!(
            bytes % elem == 0,
            "readback part {i} ({bytes} bytes) is not made of {elem}-byte elements"
        );
        let buf = self.buf.as_ref().expect("recorded");
        let raw: Vec<u8> = buf.download_range(offset as usize, bytes as usize)?;
        Ok(bytemuck::pod_collect_to_vec(&raw))
    }
}
