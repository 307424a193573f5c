//! A batch: one command buffer holding many dispatches (and fills, copies, in-stream buffer
//! updates), with a memory barrier after each and a timestamp pair around each dispatch,
//! submitted once. A submission and its wait cost several times a dispatch inside a batch
//! (docs/results.md), so a training step is one batch. `submit_async` returns without waiting, so the host can
//! record the next step while the device runs this one; the command pool, query pool and fence a
//! batch uses are reused from batch to batch.
use super::buffer::GpuBuffer;
use super::context::Gpu;
use super::frame::Frame;
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

impl Gpu {
    /// A frame from the context's spares, or a new one.
    fn take_frame(&self) -> Result<Frame> {
        let spare = self.inner.frames.lock().unwrap().pop();
        match spare {
            Some(f) => Ok(f),
            None => {
                let info = &self.inner.info;
                Frame::new(
                    &self.inner.device,
                    info.queue_family.expect("checked at start"),
                    info.timestamp_period_ns.is_some().then_some(2 * MAX_TIMED),
                )
            }
        }
    }

    /// Give a frame the device is done with back to the spares.
    fn return_frame(&self, f: Frame) {
        self.inner.frames.lock().unwrap().push(f);
    }
}

/// Commands being recorded; nothing runs until `submit` (or `submit_async`).
pub struct Batch {
    gpu: Gpu,
    /// Taken by `submit_async`; a batch dropped unsubmitted gives it back.
    frame: Option<Frame>,
    cmd: vk::CommandBuffer,
    queries: Option<vk::QueryPool>,
    timed: Vec<&'static str>,
    /// The device addresses in the recorded push constants, with the number of the buffer
    /// holding each and their kernel's name: each must still be in that buffer when the batch
    /// is submitted.
    addresses: Vec<(u64, u64, &'static str)>,
}

/// A submitted batch the host has not waited for yet. Dropping it waits.
pub struct InFlight {
    gpu: Gpu,
    frame: Option<Frame>,
    timed: Vec<&'static str>,
    /// Host time of the submission (record, submit) and of waiting for the fence.
    host: StepTimes,
    /// Whether the fence has been waited for.
    complete: bool,
}

impl Gpu {
    /// Start recording a batch.
    pub fn batch(&self) -> Result<Batch> {
        let dev = &self.inner.device;
        let frame = self.take_frame()?;
        let begun = unsafe {
            dev.reset_command_pool(frame.pool, vk::CommandPoolResetFlags::empty())
                .and_then(|_| {
                    dev.begin_command_buffer(
                        frame.cmd,
                        &vk::CommandBufferBeginInfo::default()
                            .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
                    )
                })
        };
        if let Err(e) = begun {
            frame.destroy(dev);
            return Err(e).context("starting a command buffer");
        }
        if let Some(q) = frame.queries {
            unsafe { dev.cmd_reset_query_pool(frame.cmd, q, 0, 2 * MAX_TIMED) };
        }
        let b = Batch {
            gpu: self.clone(),
            cmd: frame.cmd,
            queries: frame.queries,
            frame: Some(frame),
            timed: Vec::new(),
            addresses: Vec::new(),
        };
        // Order this batch after whatever earlier submissions on the queue still run.
        b.barrier();
        Ok(b)
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
        for &at in k.addresses {
            let at = at as usize;
            let a = u64::from_le_bytes(bytes[at..at + 8].try_into().expect("8 bytes"));
            if a != 0 {
                let buffer = self.gpu.buffer_at(a).with_context(|| {
                    format!(
                        "kernel {}: push-constant address {a:#x} is not inside a live buffer",
                        k.name
                    )
                })?;
                self.addresses.push((a, buffer, k.name));
            }
        }
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

    /// Record writing `data` (at most 65536 bytes, a multiple of 4) into `buf` at byte `offset`,
    /// in the command stream: a step's parameters written this way cannot race with an earlier
    /// step still running on the device.
    pub fn update<T: Pod>(&mut self, buf: &GpuBuffer, offset: u64, data: &[T]) -> Result<()> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        ensure!(
            bytes.len() <= 65536 && bytes.len().is_multiple_of(4) && offset.is_multiple_of(4),
            "an in-stream buffer update takes at most 65536 bytes in 4-byte words at a 4-byte \
             offset, got {} bytes at {offset}",
            bytes.len()
        );
        ensure!(
            offset + bytes.len() as u64 <= buf.size(),
            "an update of {} bytes at {offset} overruns a buffer of {}",
            bytes.len(),
            buf.size()
        );
        if !bytes.is_empty() {
            unsafe {
                self.gpu
                    .inner
                    .device
                    .cmd_update_buffer(self.cmd, buf.handle(), offset, bytes)
            };
            self.barrier();
        }
        Ok(())
    }

    /// Submit, wait for completion, and return the device time of each timed dispatch.
    pub fn submit(self) -> Result<BatchTimes> {
        self.submit_async()?.wait()
    }

    /// Submit without waiting: the host may record and submit the next batch while this one
    /// runs (batches on the queue run in order; each starts with a full barrier).
    pub fn submit_async(mut self) -> Result<InFlight> {
        // A kernel given a freed buffer's address would write memory that may belong to
        // another buffer by now (even one at the same address): refused, as a dispatch with no
        // live buffer there is when recorded.
        for &(a, buffer, kernel) in &self.addresses {
            ensure!(
                self.gpu.buffer_at(a) == Some(buffer),
                "kernel {kernel}: the buffer at push-constant address {a:#x} was dropped before \
                 its batch was submitted"
            );
        }
        let mut clock = PhaseClock::start();
        let gpu = self.gpu.clone();
        let dev = &gpu.inner.device;
        let to_host = [vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(vk::AccessFlags::HOST_READ)];
        let frame = self.frame.take().expect("a batch is submitted once");
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
        }
        let ended = unsafe { dev.end_command_buffer(self.cmd) }
            .and_then(|_| unsafe { dev.reset_fences(&[frame.fence]) });
        if let Err(e) = ended {
            frame.destroy(dev);
            return Err(e).context("ending a command buffer");
        }
        clock.mark(Phase::Record);
        let cmds = [self.cmd];
        let submit = [vk::SubmitInfo::default().command_buffers(&cmds)];
        let result = {
            let queue = gpu.inner.queue.lock().unwrap();
            unsafe { dev.queue_submit(*queue, &submit, frame.fence) }
        };
        if let Err(e) = result {
            // Never submitted: the frame is free again.
            gpu.return_frame(frame);
            return Err(e).context("submitting a batch to the Vulkan queue");
        }
        clock.mark(Phase::Submit);
        Ok(InFlight {
            gpu: gpu.clone(),
            frame: Some(frame),
            timed: std::mem::take(&mut self.timed),
            host: clock.times,
            complete: false,
        })
    }
}

impl InFlight {
    /// Wait for the batch's fence (the device is then done with it); its timestamps stay
    /// unread until [`Self::wait`].
    pub fn wait_fence(&mut self) -> Result<()> {
        if self.complete {
            return Ok(());
        }
        let mut clock = PhaseClock::start();
        let frame = self
            .frame
            .as_ref()
            .expect("a batch in flight has its frame");
        unsafe {
            self.gpu
                .inner
                .device
                .wait_for_fences(&[frame.fence], true, u64::MAX)
        }
        .context("waiting for a batch on the Vulkan queue")?;
        clock.mark(Phase::Wait);
        self.host.add(&clock.times);
        self.complete = true;
        Ok(())
    }

    /// Wait for the batch to complete; returns the device time of each timed dispatch and the
    /// host time of its submission and of the waits. (Reading a batch's timestamps once later
    /// batches are queued behind it can wait for those too — lavapipe does — so a loop with
    /// batches in flight waits for their fences first and reads the timestamps after.)
    pub fn wait(mut self) -> Result<BatchTimes> {
        // A failed wait means a lost device: the frame is not given back, so its objects are
        // never reused.
        self.wait_fence()?;
        let mut clock = PhaseClock::start();
        let gpu = self.gpu.clone();
        let inner = &gpu.inner;
        let dev = &inner.device;
        let frame = self.frame.take().expect("waited once");
        let mut times = BatchTimes::default();
        let read = match (frame.queries, self.timed.is_empty()) {
            (Some(q), false) => {
                let period = inner.info.timestamp_period_ns.unwrap_or(1.0) as f64;
                let mut raw = vec![0u64; 2 * self.timed.len()];
                // After the fence the results are available; should a driver not have them
                // yet, wait for them.
                let mut read = |flags| unsafe {
                    dev.get_query_pool_results(
                        q,
                        0,
                        &mut raw,
                        vk::QueryResultFlags::TYPE_64 | flags,
                    )
                };
                let r = match read(vk::QueryResultFlags::empty()) {
                    Err(vk::Result::NOT_READY) => read(vk::QueryResultFlags::WAIT),
                    r => r,
                };
                if r.is_ok() {
                    for (i, name) in self.timed.iter().enumerate() {
                        let ns = raw[2 * i + 1].saturating_sub(raw[2 * i]) as f64 * period;
                        inner.profile.add(name, ns);
                        times.dispatches.push((name, ns));
                    }
                }
                r
            }
            _ => Ok(()),
        };
        gpu.return_frame(frame);
        read.context("reading timestamp queries")?;
        clock.mark(Phase::Readback);
        times.host = self.host;
        times.host.add(&clock.times);
        Ok(times)
    }
}

impl Drop for InFlight {
    fn drop(&mut self) {
        if let Some(frame) = self.frame.take() {
            let dev = &self.gpu.inner.device;
            if unsafe { dev.wait_for_fences(&[frame.fence], true, u64::MAX) }.is_ok() {
                self.gpu.return_frame(frame);
            }
            // Else the device may still use the frame: its objects are not reused.
        }
    }
}

impl Drop for Batch {
    fn drop(&mut self) {
        if let Some(frame) = self.frame.take() {
            // Recorded but never submitted: ending the buffer is enough; the next batch resets
            // the pool.
            let _ = unsafe { self.gpu.inner.device.end_command_buffer(self.cmd) };
            self.gpu.return_frame(frame);
        }
    }
}
