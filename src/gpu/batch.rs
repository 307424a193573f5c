//! A batch: one command buffer holding many dispatches (and fills/copies), with a memory barrier
//! after each and a timestamp pair around each dispatch, submitted once and waited on once. One
//! submit+wait costs ~90–150 µs on lavapipe, a dispatch inside a batch ~12–30 µs, so a training
//! step is one batch.

use super::buffer::GpuBuffer;
use super::context::Gpu;
use super::step_times::{Phase, PhaseClock, StepTimes};
use crate::abi::consts::DISPATCH_ROW_GROUPS;
use crate::kernels::KernelInfo;
use anyhow::{ensure, Context, Result};
use ash::vk;
use bytemuck::Pod;

/// Dispatches timed per batch; later ones in the same batch run untimed.
const MAX_TIMED: u32 = 1024;

/// Device time of each timed dispatch of a submitted batch.
#[derive(Debug, Clone, Default)]
pub struct BatchTimes {
    /// (kernel name, device nanoseconds), in dispatch order.
    pub dispatches: Vec<(&'static str, f64)>,
    /// Host time of `submit`: ending the command buffer (record), the submission, the fence wait,
    /// reading the timestamps (readback).
    pub host: StepTimes,
}

impl BatchTimes {
    /// Total device ns spent in dispatches of `kernel`.
    pub fn kernel_ns(&self, kernel: &str) -> f64 {
        self.dispatches
            .iter()
            .filter(|(k, _)| *k == kernel)
            .map(|(_, ns)| ns)
            .sum()
    }

    /// Total device ns over all timed dispatches.
    pub fn total_ns(&self) -> f64 {
        self.dispatches.iter().map(|(_, ns)| ns).sum()
    }
}

/// Commands being recorded; nothing runs until `submit`.
pub struct Batch {
    gpu: Gpu,
    cmd: vk::CommandBuffer,
    /// The batch's own command pool: Vulkan pools need external synchronisation for recording,
    /// so one pool per batch lets batches be recorded on several threads at once.
    pool: vk::CommandPool,
    queries: Option<vk::QueryPool>,
    timed: Vec<&'static str>,
    submitted: bool,
}

impl Gpu {
    /// Start recording a batch.
    pub fn batch(&self) -> Result<Batch> {
        let dev = &self.inner.device;
        let pool = unsafe {
            dev.create_command_pool(
                &vk::CommandPoolCreateInfo::default()
                    .queue_family_index(self.inner.info.queue_family.expect("checked at start"))
                    .flags(vk::CommandPoolCreateFlags::TRANSIENT),
                None,
            )
        }
        .context("creating a command pool")?;
        let cmd = unsafe {
            dev.allocate_command_buffers(
                &vk::CommandBufferAllocateInfo::default()
                    .command_pool(pool)
                    .level(vk::CommandBufferLevel::PRIMARY)
                    .command_buffer_count(1),
            )
        };
        let cmd = match cmd {
            Ok(c) => c[0],
            Err(e) => {
                unsafe { dev.destroy_command_pool(pool, None) };
                return Err(e).context("allocating a command buffer");
            }
        };
        unsafe {
            dev.begin_command_buffer(
                cmd,
                &vk::CommandBufferBeginInfo::default()
                    .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
            )
        }?;
        let queries = if self.inner.info.timestamp_period_ns.is_some() {
            let pool = unsafe {
                dev.create_query_pool(
                    &vk::QueryPoolCreateInfo::default()
                        .query_type(vk::QueryType::TIMESTAMP)
                        .query_count(2 * MAX_TIMED),
                    None,
                )
            }?;
            unsafe { dev.cmd_reset_query_pool(cmd, pool, 0, 2 * MAX_TIMED) };
            Some(pool)
        } else {
            None
        };
        Ok(Batch {
            gpu: self.clone(),
            cmd,
            pool,
            queries,
            timed: Vec::new(),
            submitted: false,
        })
    }

    /// Run one 1-D dispatch of `n` threads and wait for it.
    pub fn run_1d<P: Pod>(&self, k: &'static KernelInfo, push: &P, n: u32) -> Result<BatchTimes> {
        let mut b = self.batch()?;
        b.dispatch_1d(k, push, n)?;
        b.submit()
    }
}

impl Batch {
    fn barrier(&self) {
        let all = vk::AccessFlags::INDIRECT_COMMAND_READ
            | vk::AccessFlags::SHADER_READ
            | vk::AccessFlags::SHADER_WRITE
            | vk::AccessFlags::TRANSFER_READ
            | vk::AccessFlags::TRANSFER_WRITE;
        let stages = vk::PipelineStageFlags::COMPUTE_SHADER
            | vk::PipelineStageFlags::TRANSFER
            | vk::PipelineStageFlags::DRAW_INDIRECT;
        let mb = [vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(all)];
        unsafe {
            self.gpu.inner.device.cmd_pipeline_barrier(
                self.cmd,
                stages,
                stages,
                vk::DependencyFlags::empty(),
                &mb,
                &[],
                &[],
            )
        };
    }

    /// Record `k` over `groups` workgroups with push constants `push`.
    pub fn dispatch<P: Pod>(
        &mut self,
        k: &'static KernelInfo,
        push: &P,
        groups: [u32; 3],
    ) -> Result<()> {
        if groups.contains(&0) {
            return Ok(());
        }
        self.record(k, bytemuck::bytes_of(push), |dev, cmd| unsafe {
            dev.cmd_dispatch(cmd, groups[0], groups[1], groups[2])
        })
    }

    /// Record `k` with its workgroup counts read on the device from the first three u32 of
    /// `args` (written by an earlier kernel of the batch).
    pub fn dispatch_indirect<P: Pod>(
        &mut self,
        k: &'static KernelInfo,
        push: &P,
        args: &GpuBuffer,
    ) -> Result<()> {
        let buf = args.handle();
        self.record(k, bytemuck::bytes_of(push), |dev, cmd| unsafe {
            dev.cmd_dispatch_indirect(cmd, buf, 0)
        })
    }

    fn record(
        &mut self,
        k: &'static KernelInfo,
        bytes: &[u8],
        dispatch: impl FnOnce(&ash::Device, vk::CommandBuffer),
    ) -> Result<()> {
        ensure!(
            bytes.len() == k.push_size as usize,
            "kernel {}: push constants of {} bytes, the kernel expects {}",
            k.name,
            bytes.len(),
            k.push_size
        );
        let (pipeline, layout) = self.gpu.pipeline(k)?;
        let dev = &self.gpu.inner.device;
        let slot = self.timed.len() as u32;
        let timed = self.queries.filter(|_| slot < MAX_TIMED);
        unsafe {
            if let Some(q) = timed {
                dev.cmd_write_timestamp(
                    self.cmd,
                    vk::PipelineStageFlags::COMPUTE_SHADER,
                    q,
                    2 * slot,
                );
            }
            dev.cmd_bind_pipeline(self.cmd, vk::PipelineBindPoint::COMPUTE, pipeline);
            if !bytes.is_empty() {
                dev.cmd_push_constants(self.cmd, layout, vk::ShaderStageFlags::COMPUTE, 0, bytes);
            }
        }
        dispatch(dev, self.cmd);
        unsafe {
            if let Some(q) = timed {
                dev.cmd_write_timestamp(
                    self.cmd,
                    vk::PipelineStageFlags::COMPUTE_SHADER,
                    q,
                    2 * slot + 1,
                );
                self.timed.push(k.name);
            }
        }
        self.barrier();
        Ok(())
    }

    /// Record `k` for `n` threads (a 2-D grid of workgroups; kernels use `flat_id()`).
    pub fn dispatch_1d<P: Pod>(&mut self, k: &'static KernelInfo, push: &P, n: u32) -> Result<()> {
        let groups = n.div_ceil(k.local_size[0]);
        // Rows of DISPATCH_ROW_GROUPS workgroups, as common.glsl's flat_id() reads them.
        let gx = groups.min(DISPATCH_ROW_GROUPS);
        let gy = groups.div_ceil(gx.max(1));
        self.dispatch(k, push, [gx, gy, 1])
    }

    /// Record zero-filling the whole buffer.
    pub fn fill_zero(&mut self, buf: &GpuBuffer) {
        self.fill_zero_range(buf, 0, vk::WHOLE_SIZE);
    }

    /// Record zero-filling `bytes` bytes (a multiple of 4, or `vk::WHOLE_SIZE`) from `offset`.
    pub fn fill_zero_range(&mut self, buf: &GpuBuffer, offset: u64, bytes: u64) {
        unsafe {
            self.gpu
                .inner
                .device
                .cmd_fill_buffer(self.cmd, buf.handle(), offset, bytes, 0)
        };
        self.barrier();
    }

    /// Record a copy of `bytes` bytes from `src` at `src_offset` to `dst` at `dst_offset`.
    pub fn copy_region(
        &mut self,
        src: &GpuBuffer,
        src_offset: u64,
        dst: &GpuBuffer,
        dst_offset: u64,
        bytes: u64,
    ) {
        let region = [vk::BufferCopy::default()
            .src_offset(src_offset)
            .dst_offset(dst_offset)
            .size(bytes)];
        unsafe {
            self.gpu
                .inner
                .device
                .cmd_copy_buffer(self.cmd, src.handle(), dst.handle(), &region)
        };
        self.barrier();
    }

    /// Submit, wait for completion, and return the device time of each timed dispatch.
    pub fn submit(mut self) -> Result<BatchTimes> {
        let mut clock = PhaseClock::start();
        let inner = &self.gpu.inner;
        let dev = &inner.device;
        let to_host = [vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(vk::AccessFlags::HOST_READ)];
        unsafe {
            dev.cmd_pipeline_barrier(
                self.cmd,
                vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::HOST,
                vk::DependencyFlags::empty(),
                &to_host,
                &[],
                &[],
            );
            dev.end_command_buffer(self.cmd)?;
        }
        clock.mark(Phase::Record);
        let fence = unsafe { dev.create_fence(&vk::FenceCreateInfo::default(), None) }?;
        let cmds = [self.cmd];
        let submit = [vk::SubmitInfo::default().command_buffers(&cmds)];
        let result = {
            let queue = inner.queue.lock().unwrap();
            unsafe { dev.queue_submit(*queue, &submit, fence) }
        };
        clock.mark(Phase::Submit);
        let result = result.and_then(|_| unsafe { dev.wait_for_fences(&[fence], true, u64::MAX) });
        unsafe { dev.destroy_fence(fence, None) };
        self.submitted = true;
        result.context("submitting a batch to the Vulkan queue")?;
        clock.mark(Phase::Wait);

        let mut times = BatchTimes::default();
        if let (Some(q), false) = (self.queries, self.timed.is_empty()) {
            let period = inner.info.timestamp_period_ns.unwrap_or(1.0) as f64;
            let mut raw = vec![0u64; 2 * self.timed.len()];
            unsafe {
                dev.get_query_pool_results(
                    q,
                    0,
                    &mut raw,
                    vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
                )
            }
            .context("reading timestamp queries")?;
            for (i, name) in self.timed.iter().enumerate() {
                let ns = raw[2 * i + 1].saturating_sub(raw[2 * i]) as f64 * period;
                inner.profile.add(name, ns);
                times.dispatches.push((name, ns));
            }
        }
        clock.mark(Phase::Readback);
        times.host = clock.times;
        Ok(times)
    }
}

impl Drop for Batch {
    fn drop(&mut self) {
        let inner = &self.gpu.inner;
        unsafe {
            if !self.submitted {
                // Recorded but never submitted: ending it is enough to free it.
                let _ = inner.device.end_command_buffer(self.cmd);
            }
            if let Some(q) = self.queries {
                inner.device.destroy_query_pool(q, None);
            }
            // Destroying the pool frees its command buffer.
            inner.device.destroy_command_pool(self.pool, None);
        }
    }
}
