//! What a batch records into and submits with, reused from batch to batch.

use anyhow::{Context, Result};
use ash::vk;

/// A command pool with its one command buffer, timestamp queries and fence: what a batch records
/// into and submits with. Frames are created on first need and reused by later batches (kept in
/// the context), so a training step creates no Vulkan object.
pub(super) struct Frame {
    pub pool: vk::CommandPool,
    pub cmd: vk::CommandBuffer,
    pub queries: Option<vk::QueryPool>,
    pub fence: vk::Fence,
}

impl Frame {
    /// A frame on `dev` for the queue family `queue_family`, with `queries` timestamp queries
    /// (`None`: the device has no timestamps).
    pub(super) fn new(dev: &ash::Device, queue_family: u32, queries: Option<u32>) -> Result<Frame> {
        // Vulkan pools need external synchronisation for recording, so one pool per frame lets
        // batches be recorded on several threads at once.
        let pool = unsafe {
            dev.create_command_pool(
                &vk::CommandPoolCreateInfo::default()
                    .queue_family_index(queue_family)
                    .flags(vk::CommandPoolCreateFlags::TRANSIENT),
                None,
            )
        }
        .context("creating a command pool")?;
        let mut frame = Frame {
            pool,
            cmd: vk::CommandBuffer::null(),
            queries: None,
            fence: vk::Fence::null(),
        };
        // On an error below, `destroy` frees what was created.
        let made = (|| -> Result<()> {
            frame.cmd = unsafe {
                dev.allocate_command_buffers(
                    &vk::CommandBufferAllocateInfo::default()
                        .command_pool(pool)
                        .level(vk::CommandBufferLevel::PRIMARY)
                        .command_buffer_count(1),
                )
            }
            .context("allocating a command buffer")?[0];
            frame.fence = unsafe { dev.create_fence(&vk::FenceCreateInfo::default(), None) }
                .context("creating a fence")?;
            if let Some(count) = queries {
                frame.queries = Some(
                    unsafe {
                        dev.create_query_pool(
                            &vk::QueryPoolCreateInfo::default()
                                .query_type(vk::QueryType::TIMESTAMP)
                                .query_count(count),
                            None,
                        )
                    }
                    .context("creating a timestamp query pool")?,
                );
            }
            Ok(())
        })();
        match made {
            Ok(()) => Ok(frame),
            Err(e) => {
                frame.destroy(dev);
                Err(e)
            }
        }
    }

    /// Free the frame's objects (the device must be done with them).
    pub(super) fn destroy(self, dev: &ash::Device) {
        unsafe {
            if let Some(q) = self.queries {
                dev.destroy_query_pool(q, None);
            }
            if self.fence != vk::Fence::null() {
                dev.destroy_fence(self.fence, None);
            }
            // Destroying the pool frees its command buffer.
            dev.destroy_command_pool(self.pool, None);
        }
    }
}
