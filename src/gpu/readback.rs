//! Per-step results brought back without a submission of their own: a ring of slots in one
//! host-visible buffer, each holding one step's parts (loss sums, regulariser losses, counters)
//! at fixed offsets. A step's batch writes its slot (by copies, or a kernel writing there
//! directly); the host reads the slots of several steps at once, after their batches completed.
//! (Reading a device buffer directly costs a staging buffer and a submission where device memory
//! is not host-visible, as on a discrete GPU.)

use super::{Batch, Gpu, GpuBuffer};
use anyhow::{ensure, Result};
use bytemuck::Pod;

/// Slots of a training backend's ring: the steps it can run before their figures must be read.
pub const STEP_SLOTS: usize = 32;

/// A host-visible ring of `slots` slots, each made of the same parts.
pub struct Readback {
    buf: GpuBuffer,
    /// (offset in the slot, bytes) of each part.
    parts: Vec<(u64, u64)>,
    slot_bytes: u64,
    slots: usize,
}

impl Readback {
    /// A ring of `slots` slots holding parts of `part_bytes` bytes each (each starts on a 16-byte
    /// boundary: copies need 4, kernels' scalar loads at most 16).
    pub fn new(gpu: &Gpu, part_bytes: &[u64], slots: usize) -> Result<Self> {
        let mut at = 0;
        let parts = part_bytes
            .iter()
            .map(|&bytes| {
                let part = (at, bytes);
                at += bytes.next_multiple_of(16);
                part
            })
            .collect();
        let slots = slots.max(1);
        Ok(Readback {
            buf: gpu.device_to_host::<u32>((at as usize * slots / 4).max(1))?,
            parts,
            slot_bytes: at,
            slots,
        })
    }

    /// Slots in the ring.
    pub fn slots(&self) -> usize {
        self.slots
    }

    /// Byte offset of part `part` of slot `slot` in the ring buffer.
    fn offset(&self, slot: usize, part: usize) -> u64 {
        slot as u64 * self.slot_bytes + self.parts[part].0
    }

    /// Device address of part `part` of slot `slot`, for a kernel that writes it.
    pub fn address(&self, slot: usize, part: usize) -> u64 {
        self.buf.address() + self.offset(slot, part)
    }

    /// Record, at this point of `b`, a copy of part `part`'s bytes from `src` at byte `src_offset`
    /// into slot `slot`.
    pub fn copy(&self, b: &mut Batch, slot: usize, part: usize, src: &GpuBuffer, src_offset: u64) {
        let bytes = self.parts[part].1;
        b.copy_region(src, src_offset, &self.buf, self.offset(slot, part), bytes);
    }

    /// Part `part` of slot `slot` as `T`s, once the batch that wrote it has completed.
    pub fn part<T: Pod>(&self, slot: usize, part: usize) -> Result<Vec<T>> {
        ensure!(
            slot < self.slots && part < self.parts.len(),
            "readback slot {slot} part {part} does not exist"
        );
        let bytes = self.parts[part].1;
        let elem = std::mem::size_of::<T>() as u64;
        ensure!(
            bytes.is_multiple_of(elem),
            "readback part {part} ({bytes} bytes) is not made of {elem}-byte elements"
        );
        let raw: Vec<u8> = self
            .buf
            .download_range(self.offset(slot, part) as usize, bytes as usize)?;
        Ok(bytemuck::pod_collect_to_vec(&raw))
    }
}
