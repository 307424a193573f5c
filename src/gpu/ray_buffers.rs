//! Per-batch ray buffers of the Vulkan backends: rays (6 floats each), their target colours (3
//! floats each) and a per-ray output whose size the backend chooses, grown to the next power of
//! two of rays when a batch does not fit. Rays and targets live in host-visible memory, so an
//! upload is a copy into their mapping, with no staging buffer or submission on any device. (A
//! training batch drawn on the device lives in `TrainViewBuffers` instead.)

use super::{Gpu, GpuBuffer};
use anyhow::Result;

/// Ray, target and per-ray output buffers, allocated by the first upload.
pub struct RayBuffers {
    /// Bytes of output per ray.
    out_bytes: usize,
    bufs: Option<Allocated>,
}

struct Allocated {
    /// Rays the buffers hold.
    capacity: usize,
    rays: GpuBuffer,
    targets: GpuBuffer,
    out: GpuBuffer,
}

impl RayBuffers {
    /// No buffers yet; each ray will have `out_bytes` bytes of output.
    pub fn new(out_bytes: usize) -> Self {
        RayBuffers {
            out_bytes,
            bufs: None,
        }
    }

    /// Writes `rays` and, when given, `targets` into buffers holding at least as many rays (and at
    /// least one). Returns the device addresses of the rays, targets and per-ray output.
    pub fn upload(&mut self, gpu: &Gpu, rays: &[f32], targets: Option<&[f32]>) -> Result<[u64; 3]> {
        let addrs = self.reserve(gpu, rays.len() / 6)?;
        let b = self.bufs.as_ref().expect("allocated by reserve");
        b.rays.write(rays)?;
        if let Some(t) = targets {
            b.targets.write(t)?;
        }
        Ok(addrs)
    }

    /// Buffers holding at least `n` rays (and at least one). Returns the device addresses of the
    /// rays, targets and per-ray output.
    pub fn reserve(&mut self, gpu: &Gpu, n: usize) -> Result<[u64; 3]> {
        let n = n.max(1);
        if self.bufs.as_ref().is_none_or(|b| b.capacity < n) {
            let cap = n.next_power_of_two();
            self.bufs = Some(Allocated {
                capacity: cap,
                rays: gpu.host_to_device::<f32>(6 * cap)?,
                targets: gpu.host_to_device::<f32>(3 * cap)?,
                out: gpu.zeros::<u8>(self.out_bytes * cap)?,
            });
        }
        let b = self.bufs.as_ref().expect("just set");
        Ok([b.rays.address(), b.targets.address(), b.out.address()])
    }

    /// The per-ray output buffer (of the last upload's batch).
    ///
    /// # Panics
    /// Before the first upload.
    pub fn out(&self) -> &GpuBuffer {
        &self.bufs.as_ref().expect("allocated by upload").out
    }
}
