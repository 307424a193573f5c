//! Device buffers: an RAII owner over a gpu-allocator allocation with its device address, plus
//! upload/download that write the mapping directly where the memory is host-visible (lavapipe's
//! only memory type) and go through a staging buffer where it is not (a discrete GPU).

use super::context::Gpu;
use anyhow::{Context, Result};
use ash::vk;
use bytemuck::Pod;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};
use gpu_allocator::MemoryLocation;

/// A device address as the kernels' structs hold it (low, high 32 bits).
pub fn address_words(a: u64) -> [u32; 2] {
    [a as u32, (a >> 32) as u32]
}

/// A storage buffer on the device, freed when dropped. Kernels see it through `address()`.
pub struct GpuBuffer {
    gpu: Gpu,
    buffer: vk::Buffer,
    allocation: Option<Allocation>,
    /// Device memory is reached through staging when not host-visible (or when forced).
    device_local: bool,
    size: u64,
    address: u64,
}

impl GpuBuffer {
    pub(super) fn new(gpu: &Gpu, size: u64, location: MemoryLocation, name: &str) -> Result<Self> {
        let inner = &gpu.inner;
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER
            | vk::BufferUsageFlags::INDIRECT_BUFFER
            | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS
            | vk::BufferUsageFlags::TRANSFER_SRC
            | vk::BufferUsageFlags::TRANSFER_DST;
        let buffer = unsafe {
            inner.device.create_buffer(
                &vk::BufferCreateInfo::default()
                    .size(size.max(4))
                    .usage(usage)
                    .sharing_mode(vk::SharingMode::EXCLUSIVE),
                None,
            )
        }
        .with_context(|| format!("creating a {size}-byte buffer ({name})"))?;
        let requirements = unsafe { inner.device.get_buffer_memory_requirements(buffer) };
        let allocation = inner
            .allocator
            .lock()
            .unwrap()
            .allocate(&AllocationCreateDesc {
                name,
                requirements,
                location,
                linear: true,
                allocation_scheme: AllocationScheme::GpuAllocatorManaged,
            });
        let allocation = match allocation {
            Ok(a) => a,
            Err(e) => {
                unsafe { inner.device.destroy_buffer(buffer, None) };
                return Err(e)
                    .with_context(|| format!("allocating {size} bytes of device memory ({name})"));
            }
        };
        unsafe {
            inner
                .device
                .bind_buffer_memory(buffer, allocation.memory(), allocation.offset())
        }?;
        let address = unsafe {
            inner
                .device
                .get_buffer_device_address(&vk::BufferDeviceAddressInfo::default().buffer(buffer))
        };
        inner
            .live_buffers
            .lock()
            .unwrap()
            .insert(address, address + size.max(4));
        let buf = GpuBuffer {
            gpu: gpu.clone(),
            buffer,
            allocation: Some(allocation),
            device_local: location == MemoryLocation::GpuOnly,
            size,
            address,
        };
        // Kernels read 64-bit words from buffer starts (rmsprop.glsl's RMSPROP_UPDATE_SH27, the
        // normal regulariser's tables): every allocation is at least 16-byte aligned in Vulkan
        // practice; refuse a device where it is not rather than read misaligned words
        // (dropping `buf` frees it).
        anyhow::ensure!(
            address % 16 == 0,
            "buffer {name}: device address {address:#x} is not 16-byte aligned"
        );
        Ok(buf)
    }

    /// Device address to put in a kernel's push constants.
    pub fn address(&self) -> u64 {
        self.address
    }

    /// Size in bytes, as requested (the allocation holds at least 4).
    pub fn size(&self) -> u64 {
        self.size
    }

    pub(super) fn handle(&self) -> vk::Buffer {
        self.buffer
    }

    fn mapped(&self) -> Option<*mut u8> {
        if self.device_local && self.gpu.inner.force_staging {
            return None;
        }
        self.allocation
            .as_ref()
            .and_then(|a| a.mapped_ptr())
            .map(|p| p.as_ptr() as *mut u8)
    }

    /// Copy `data` to the start of the buffer (the device must not be using it).
    pub fn write<T: Pod>(&self, data: &[T]) -> Result<()> {
        self.write_at(0, data)
    }

    /// Copy `data` into the buffer from byte `offset` on (a multiple of 4; the device must not be
    /// using the buffer).
    pub fn write_at<T: Pod>(&self, offset: u64, data: &[T]) -> Result<()> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        anyhow::ensure!(
            offset.is_multiple_of(4) && offset + bytes.len() as u64 <= self.size,
            "write of {} bytes at {offset} into a {}-byte buffer",
            bytes.len(),
            self.size
        );
        if bytes.is_empty() {
            return Ok(());
        }
        if let Some(p) = self.mapped() {
            unsafe {
                std::ptr::copy_nonoverlapping(bytes.as_ptr(), p.add(offset as usize), bytes.len())
            };
            return Ok(());
        }
        let staging = GpuBuffer::new(
            &self.gpu,
            bytes.len() as u64,
            MemoryLocation::CpuToGpu,
            "staging-up",
        )?;
        staging.write(bytes)?;
        let mut b = self.gpu.batch()?;
        b.copy_region(&staging, 0, self, offset, bytes.len() as u64);
        b.submit()?;
        Ok(())
    }

    /// Read the whole buffer as `T`s (the device must be done with it).
    pub fn download<T: Pod>(&self) -> Result<Vec<T>> {
        self.download_range(0, self.size as usize / std::mem::size_of::<T>())
    }

    /// Read `count` `T`s starting at element `first` (the device must be done with them).
    pub fn download_range<T: Pod>(&self, first: usize, count: usize) -> Result<Vec<T>> {
        let elem = std::mem::size_of::<T>();
        let (offset, bytes) = ((first * elem) as u64, (count * elem) as u64);
        anyhow::ensure!(
            offset + bytes <= self.size,
            "read of {bytes} bytes at {offset} from a {}-byte buffer",
            self.size
        );
        let mut out = vec![T::zeroed(); count];
        let dst: &mut [u8] = bytemuck::cast_slice_mut(&mut out);
        if dst.is_empty() {
            return Ok(out);
        }
        if let Some(p) = self.mapped() {
            unsafe {
                std::ptr::copy_nonoverlapping(p.add(offset as usize), dst.as_mut_ptr(), dst.len())
            };
            return Ok(out);
        }
        let staging = GpuBuffer::new(&self.gpu, bytes, MemoryLocation::GpuToCpu, "staging-down")?;
        let mut b = self.gpu.batch()?;
        b.copy_region(self, offset, &staging, 0, bytes);
        b.submit()?;
        let p = staging
            .mapped()
            .context("staging buffer is not host-visible")?;
        unsafe { std::ptr::copy_nonoverlapping(p, dst.as_mut_ptr(), dst.len()) };
        Ok(out)
    }
}

impl Drop for GpuBuffer {
    fn drop(&mut self) {
        let inner = &self.gpu.inner;
        // Out of the live ranges before the memory is freed: a buffer allocated on another
        // thread right after the free may get the same address.
        inner.live_buffers.lock().unwrap().remove(self.address);
        unsafe { inner.device.destroy_buffer(self.buffer, None) };
        if let Some(a) = self.allocation.take() {
            // A free can only fail on a foreign allocation; nothing to recover in a destructor.
            let _ = inner.allocator.lock().unwrap().free(a);
        }
    }
}

impl Gpu {
    /// A device buffer holding `data`.
    pub fn upload<T: Pod>(&self, data: &[T]) -> Result<GpuBuffer> {
        let bytes = std::mem::size_of_val(data) as u64;
        let buf = GpuBuffer::new(self, bytes, MemoryLocation::GpuOnly, "upload")?;
        buf.write(data)?;
        Ok(buf)
    }

    /// A device buffer holding `data`, or one zero element when `data` is empty (a buffer a
    /// kernel binds but reads nothing of).
    pub fn upload_nonempty<T: Pod>(&self, data: &[T]) -> Result<GpuBuffer> {
        if data.is_empty() {
            self.zeros::<T>(1)
        } else {
            self.upload(data)
        }
    }

    /// A zero-filled device buffer of `len` elements of `T`.
    pub fn zeros<T: Pod>(&self, len: usize) -> Result<GpuBuffer> {
        self.zeros_in::<T>(len, MemoryLocation::GpuOnly, "zeros")
    }

    /// A zero-filled buffer of `len` elements of `T` in host-visible memory that the host writes
    /// and kernels read (per-step inputs: rays, targets, parameters). Writing it is a copy into
    /// its mapping on every device, with no staging buffer and no submission.
    pub fn host_to_device<T: Pod>(&self, len: usize) -> Result<GpuBuffer> {
        self.zeros_in::<T>(len, MemoryLocation::CpuToGpu, "host-to-device")
    }

    /// A zero-filled buffer of `len` elements of `T` in host-visible memory that copies recorded
    /// in a batch fill and the host reads after it (per-step results); reading it is a copy from
    /// its mapping on every device, with no staging buffer and no submission.
    pub fn device_to_host<T: Pod>(&self, len: usize) -> Result<GpuBuffer> {
        self.zeros_in::<T>(len, MemoryLocation::GpuToCpu, "device-to-host")
    }

    fn zeros_in<T: Pod>(&self, len: usize, at: MemoryLocation, name: &str) -> Result<GpuBuffer> {
        let bytes = (len * std::mem::size_of::<T>()) as u64;
        let buf = GpuBuffer::new(self, bytes, at, name)?;
        let mut b = self.batch()?;
        b.fill_zero(&buf);
        b.submit()?;
        Ok(buf)
    }
}
