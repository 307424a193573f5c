//! Physical-device discovery: what each Vulkan device offers (for `alphasurf devices`), which one
//! to use by default, and the feature checks that decide whether a device can run our kernels.

use ash::vk;
use std::ffi::CStr;

/// What we know about one Vulkan physical device.
#[derive(Debug, Clone, serde::Serialize)]
pub struct DeviceInfo {
    /// Index in Vulkan's enumeration order (what `--device N` selects).
    pub index: usize,
    pub name: String,
    pub kind: DeviceKind,
    pub driver: String,
    pub api_version: String,
    /// Sum of device-local heap sizes in bytes.
    pub device_local_bytes: u64,
    pub subgroup_size: u32,
    /// `shaderBufferFloat32AtomicAdd` (VK_EXT_shader_atomic_float).
    pub float_atomic_add: bool,
    pub max_storage_buffer_range: u32,
    pub max_push_constants: u32,
    pub buffer_device_address: bool,
    pub shader_int64: bool,
    pub scalar_block_layout: bool,
    /// Nanoseconds per timestamp tick; `None` when the compute queue has no timestamps.
    pub timestamp_period_ns: Option<f32>,
    /// Whether a memory type is both device-local and host-visible (no staging needed).
    pub unified_memory: bool,
    /// Compute queue family index, if any.
    #[serde(skip)]
    pub queue_family: Option<u32>,
}

impl DeviceInfo {
    /// Why this device cannot run alphasurf's kernels, if it cannot (missing Vulkan 1.2 features
    /// every kernel needs). Float atomics are checked separately, per kernel.
    pub fn missing_requirements(&self) -> Option<String> {
        let mut missing = Vec::new();
        if self.queue_family.is_none() {
            missing.push("a compute queue");
        }
        if !self.buffer_device_address {
            missing.push("bufferDeviceAddress");
        }
        if !self.shader_int64 {
            missing.push("shaderInt64");
        }
        if !self.scalar_block_layout {
            missing.push("scalarBlockLayout");
        }
        (!missing.is_empty()).then(|| missing.join(", "))
    }

    fn preference(&self) -> u32 {
        match self.kind {
            DeviceKind::Discrete => 0,
            DeviceKind::Integrated => 1,
            DeviceKind::Virtual => 2,
            DeviceKind::Cpu => 3,
            DeviceKind::Other => 4,
        }
    }
}

/// A Vulkan physical device's type; serialised as its lowercase variant name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DeviceKind {
    Discrete,
    Integrated,
    Virtual,
    /// A CPU implementation of Vulkan (Mesa lavapipe).
    Cpu,
    Other,
}

impl DeviceKind {
    fn of(t: vk::PhysicalDeviceType) -> DeviceKind {
        match t {
            vk::PhysicalDeviceType::DISCRETE_GPU => DeviceKind::Discrete,
            vk::PhysicalDeviceType::INTEGRATED_GPU => DeviceKind::Integrated,
            vk::PhysicalDeviceType::VIRTUAL_GPU => DeviceKind::Virtual,
            vk::PhysicalDeviceType::CPU => DeviceKind::Cpu,
            _ => DeviceKind::Other,
        }
    }

    /// The lowercase name `devices` prints.
    pub fn name(self) -> &'static str {
        match self {
            DeviceKind::Discrete => "discrete",
            DeviceKind::Integrated => "integrated",
            DeviceKind::Virtual => "virtual",
            DeviceKind::Cpu => "cpu",
            DeviceKind::Other => "other",
        }
    }
}

impl std::fmt::Display for DeviceKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.pad(self.name())
    }
}

fn has_extension(instance: &ash::Instance, pd: vk::PhysicalDevice, name: &CStr) -> bool {
    unsafe { instance.enumerate_device_extension_properties(pd) }
        .unwrap_or_default()
        .iter()
        .any(|e| e.extension_name_as_c_str() == Ok(name))
}

/// Query one physical device.
pub fn query(instance: &ash::Instance, pd: vk::PhysicalDevice, index: usize) -> DeviceInfo {
    let atomic_ext = has_extension(instance, pd, ash::ext::shader_atomic_float::NAME);
    let mut subgroup = vk::PhysicalDeviceSubgroupProperties::default();
    let mut driver = vk::PhysicalDeviceDriverProperties::default();
    let mut props2 = vk::PhysicalDeviceProperties2::default()
        .push_next(&mut subgroup)
        .push_next(&mut driver);
    unsafe { instance.get_physical_device_properties2(pd, &mut props2) };
    let props = props2.properties;

    let mut f12 = vk::PhysicalDeviceVulkan12Features::default();
    let mut fatomic = vk::PhysicalDeviceShaderAtomicFloatFeaturesEXT::default();
    let mut feats2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut f12);
    if atomic_ext {
        feats2 = feats2.push_next(&mut fatomic);
    }
    unsafe { instance.get_physical_device_features2(pd, &mut feats2) };
    let shader_int64 = feats2.features.shader_int64 == vk::TRUE;

    let mem = unsafe { instance.get_physical_device_memory_properties(pd) };
    let device_local_bytes = mem.memory_heaps[..mem.memory_heap_count as usize]
        .iter()
        .filter(|h| h.flags.contains(vk::MemoryHeapFlags::DEVICE_LOCAL))
        .map(|h| h.size)
        .sum();
    let unified_memory = mem.memory_types[..mem.memory_type_count as usize]
        .iter()
        .any(|t| {
            t.property_flags.contains(
                vk::MemoryPropertyFlags::DEVICE_LOCAL
                    | vk::MemoryPropertyFlags::HOST_VISIBLE
                    | vk::MemoryPropertyFlags::HOST_COHERENT,
            )
        });

    let families = unsafe { instance.get_physical_device_queue_family_properties(pd) };
    let queue_family = families
        .iter()
        .position(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE))
        .map(|i| i as u32);
    let timestamp_period_ns = queue_family
        .filter(|&q| families[q as usize].timestamp_valid_bits > 0)
        .map(|_| props.limits.timestamp_period);

    let v = props.api_version;
    DeviceInfo {
        index,
        name: props
            .device_name_as_c_str()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default(),
        kind: DeviceKind::of(props.device_type),
        driver: format!(
            "{} {}",
            driver
                .driver_name_as_c_str()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default(),
            driver
                .driver_info_as_c_str()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default()
        )
        .trim()
        .to_string(),
        api_version: format!(
            "{}.{}.{}",
            vk::api_version_major(v),
            vk::api_version_minor(v),
            vk::api_version_patch(v)
        ),
        device_local_bytes,
        subgroup_size: subgroup.subgroup_size,
        float_atomic_add: atomic_ext && fatomic.shader_buffer_float32_atomic_add == vk::TRUE,
        max_storage_buffer_range: props.limits.max_storage_buffer_range,
        max_push_constants: props.limits.max_push_constants_size,
        buffer_device_address: f12.buffer_device_address == vk::TRUE,
        shader_int64,
        scalar_block_layout: f12.scalar_block_layout == vk::TRUE,
        timestamp_period_ns,
        unified_memory,
        queue_family,
    }
}

/// The default choice: among devices that meet the requirements, prefer discrete, then integrated,
/// then virtual GPUs, then CPU implementations (lavapipe); ties keep enumeration order.
pub fn pick_default(devices: &[DeviceInfo]) -> Option<usize> {
    devices
        .iter()
        .filter(|d| d.missing_requirements().is_none())
        .min_by_key(|d| (d.preference(), d.index))
        .map(|d| d.index)
}
