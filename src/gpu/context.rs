//! The Vulkan context: logical device, compute queue, allocator, and the compute
//! pipelines built lazily from the kernel table (push constants only; buffers by device address).

use super::device::{self, DeviceInfo};
use super::frame::Frame;
use super::instance::Instance;
use super::profile::Profile;
use crate::kernels::KernelInfo;
use anyhow::{anyhow, bail, Context, Result};
use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};
use std::collections::{BTreeMap, HashMap};
use std::mem::ManuallyDrop;
use std::sync::{Arc, Mutex};

/// How to open the Vulkan device.
#[derive(Debug, Clone, Default)]
pub struct GpuOptions {
    /// Device index from `alphasurf devices`; `None` picks the default.
    pub device: Option<usize>,
    /// Enable the Khronos validation layer when installed (messages are collected).
    pub validation: bool,
    /// Move data through staging buffers even where device memory is host-visible, as on a
    /// discrete GPU (lets the staging path be tested on lavapipe).
    pub force_staging: bool,
}

pub(super) struct Pipeline {
    pub pipeline: vk::Pipeline,
    pub layout: vk::PipelineLayout,
}

pub(super) struct Inner {
    pub instance: Instance,
    pub info: DeviceInfo,
    pub device: ash::Device,
    pub queue: Mutex<vk::Queue>,
    pub allocator: ManuallyDrop<Mutex<Allocator>>,
    pub pipelines: Mutex<HashMap<&'static str, Pipeline>>,
    /// Spare batch frames (command pool, buffer, queries, fence) for the next batches.
    pub frames: Mutex<Vec<Frame>>,
    pub live_buffers: Mutex<LiveBuffers>,
    pub profile: Profile,
    pub force_staging: bool,
}

/// The device address ranges of the buffers allocated and not yet dropped, each with a number
/// no other buffer of the context gets (an address alone may come back with the next buffer).
#[derive(Default)]
pub(super) struct LiveBuffers {
    /// start → (end, number).
    ranges: BTreeMap<u64, (u64, u64)>,
    next: u64,
}

impl LiveBuffers {
    /// A new buffer's range [start, end), under the next number.
    pub fn insert(&mut self, start: u64, end: u64) {
        self.next += 1;
        self.ranges.insert(start, (end, self.next));
    }

    /// The buffer starting at `start` is dropped.
    pub fn remove(&mut self, start: u64) {
        self.ranges.remove(&start);
    }

    /// The number of the buffer whose range holds `a`.
    pub fn containing(&self, a: u64) -> Option<u64> {
        let (_, &(end, number)) = self.ranges.range(..=a).next_back()?;
        (a < end).then_some(number)
    }
}

/// A Vulkan compute device ready to run alphasurf kernels. Cheap to clone (shared handle).
#[derive(Clone)]
pub struct Gpu {
    pub(super) inner: Arc<Inner>,
}

/// List every Vulkan device (for `alphasurf devices`).
pub fn list_devices() -> Result<Vec<DeviceInfo>> {
    let inst = Instance::new(false)?;
    Ok(inst
        .physical_devices()?
        .into_iter()
        .enumerate()
        .map(|(i, pd)| device::query(&inst.instance, pd, i))
        .collect())
}

impl Gpu {
    /// Open a device: `opts.device`, else the best one that meets the requirements.
    pub fn new(opts: &GpuOptions) -> Result<Gpu> {
        let instance = Instance::new(opts.validation)?;
        let pds = instance.physical_devices()?;
        let infos: Vec<DeviceInfo> = pds
            .iter()
            .enumerate()
            .map(|(i, &pd)| device::query(&instance.instance, pd, i))
            .collect();
        if infos.is_empty() {
            bail!(
                "no Vulkan device found; on a machine without a GPU install Mesa's lavapipe \
                 (`apt-get install mesa-vulkan-drivers`)"
            );
        }
        let index = match opts.device {
            Some(i) => {
                let info = infos.get(i).ok_or_else(|| {
                    anyhow!(
                        "--device {i}: there are only {} Vulkan devices (see `alphasurf devices`)",
                        infos.len()
                    )
                })?;
                if let Some(m) = info.missing_requirements() {
                    bail!(
                        "device {i} ({}) lacks {m}, which every kernel needs",
                        info.name
                    );
                }
                i
            }
            None => device::pick_default(&infos).ok_or_else(|| {
                anyhow!(
                    "no Vulkan device offers bufferDeviceAddress, shaderInt64 and \
                     scalarBlockLayout (Vulkan 1.2); devices: {}",
                    infos
                        .iter()
                        .map(|d| format!(
                            "{} ({})",
                            d.name,
                            d.missing_requirements().unwrap_or_default()
                        ))
                        .collect::<Vec<_>>()
                        .join("; ")
                )
            })?,
        };
        let info = infos[index].clone();
        let pd = pds[index];
        let qf = info.queue_family.expect("checked by missing_requirements");

        let priorities = [1.0f32];
        let queues = [vk::DeviceQueueCreateInfo::default()
            .queue_family_index(qf)
            .queue_priorities(&priorities)];
        let features = vk::PhysicalDeviceFeatures::default().shader_int64(true);
        let mut f12 = vk::PhysicalDeviceVulkan12Features::default()
            .buffer_device_address(true)
            .scalar_block_layout(true);
        let mut fatomic = vk::PhysicalDeviceShaderAtomicFloatFeaturesEXT::default()
            .shader_buffer_float32_atomic_add(true);
        let mut exts = Vec::new();
        let mut ci = vk::DeviceCreateInfo::default()
            .queue_create_infos(&queues)
            .enabled_features(&features)
            .push_next(&mut f12);
        if info.float_atomic_add {
            exts.push(ash::ext::shader_atomic_float::NAME.as_ptr());
            ci = ci.push_next(&mut fatomic);
        }
        ci = ci.enabled_extension_names(&exts);
        let device = unsafe { instance.instance.create_device(pd, &ci, None) }
            .with_context(|| format!("vkCreateDevice failed on {}", info.name))?;
        let queue = unsafe { device.get_device_queue(qf, 0) };
        let allocator = Allocator::new(&AllocatorCreateDesc {
            instance: instance.instance.clone(),
            device: device.clone(),
            physical_device: pd,
            debug_settings: Default::default(),
            buffer_device_address: true,
            allocation_sizes: Default::default(),
        })
        .context("creating the memory allocator")?;
        Ok(Gpu {
            inner: Arc::new(Inner {
                instance,
                info,
                device,
                queue: Mutex::new(queue),
                allocator: ManuallyDrop::new(Mutex::new(allocator)),
                pipelines: Mutex::new(HashMap::new()),
                frames: Mutex::new(Vec::new()),
                live_buffers: Mutex::new(LiveBuffers::default()),
                profile: Profile::default(),
                force_staging: opts.force_staging,
            }),
        })
    }

    /// The device in use.
    pub fn info(&self) -> &DeviceInfo {
        &self.inner.info
    }

    /// Whether the Khronos validation layer is active on this context.
    pub fn validation_active(&self) -> bool {
        self.inner.instance.validation_active()
    }

    /// Validation-layer warnings and errors collected so far (empty without validation).
    pub fn validation_messages(&self) -> Vec<String> {
        self.inner.instance.messages()
    }

    /// Buffers allocated through this context and not yet dropped (leak check in tests).
    pub fn live_buffers(&self) -> usize {
        self.inner.live_buffers.lock().unwrap().ranges.len()
    }

    /// The buffer (its [`LiveBuffers`] number) that holds device address `a`, if one does.
    pub(super) fn buffer_at(&self, a: u64) -> Option<u64> {
        self.inner.live_buffers.lock().unwrap().containing(a)
    }

    /// Accumulated per-kernel device times of every batch submitted so far.
    pub fn profile(&self) -> &Profile {
        &self.inner.profile
    }

    /// Pipeline of `k`, created on first use.
    pub(super) fn pipeline(
        &self,
        k: &'static KernelInfo,
    ) -> Result<(vk::Pipeline, vk::PipelineLayout)> {
        let mut map = self.inner.pipelines.lock().unwrap();
        if let Some(p) = map.get(k.name) {
            return Ok((p.pipeline, p.layout));
        }
        if k.float_atomics && !self.inner.info.float_atomic_add {
            bail!(
                "kernel {} needs float atomic add (shaderBufferFloat32AtomicAdd), which {} lacks: \
                 the gradient-scatter kernels cannot run on this device; use `--backend cpu` or \
                 another device (`alphasurf devices`)",
                k.name,
                self.inner.info.name
            );
        }
        if k.push_size > self.inner.info.max_push_constants {
            bail!(
                "kernel {} has a {}-byte push-constant block; {} allows {}",
                k.name,
                k.push_size,
                self.inner.info.name,
                self.inner.info.max_push_constants
            );
        }
        let dev = &self.inner.device;
        let module = unsafe {
            dev.create_shader_module(&vk::ShaderModuleCreateInfo::default().code(k.spirv), None)
        }
        .with_context(|| format!("creating the shader module of {}", k.name))?;
        let ranges = [vk::PushConstantRange::default()
            .stage_flags(vk::ShaderStageFlags::COMPUTE)
            .offset(0)
            .size(k.push_size)];
        let layout_ci = if k.push_size > 0 {
            vk::PipelineLayoutCreateInfo::default().push_constant_ranges(&ranges)
        } else {
            vk::PipelineLayoutCreateInfo::default()
        };
        let layout = unsafe { dev.create_pipeline_layout(&layout_ci, None) }?;
        let stage = vk::PipelineShaderStageCreateInfo::default()
            .stage(vk::ShaderStageFlags::COMPUTE)
            .module(module)
            .name(c"main");
        let ci = [vk::ComputePipelineCreateInfo::default()
            .stage(stage)
            .layout(layout)];
        let result = unsafe { dev.create_compute_pipelines(vk::PipelineCache::null(), &ci, None) };
        unsafe { dev.destroy_shader_module(module, None) };
        let pipeline =
            result.map_err(|(_, e)| anyhow!("creating the pipeline of {}: {e}", k.name))?[0];
        map.insert(k.name, Pipeline { pipeline, layout });
        Ok((pipeline, layout))
    }
}

impl Drop for Inner {
    fn drop(&mut self) {
        unsafe {
            let _ = self.device.device_wait_idle();
            for f in self.frames.get_mut().unwrap().drain(..) {
                f.destroy(&self.device);
            }
            for (_, p) in self.pipelines.get_mut().unwrap().drain() {
                self.device.destroy_pipeline(p.pipeline, None);
                self.device.destroy_pipeline_layout(p.layout, None);
            }
            // The allocator frees its memory blocks; it must go before the device.
            ManuallyDrop::drop(&mut self.allocator);
            self.device.destroy_device(None);
        }
    }
}
