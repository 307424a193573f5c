//! `alphasurf devices`: every Vulkan device and the CPU backend.

use crate::gpu::{list_devices, DeviceInfo, DeviceKind};
use anyhow::Result;

fn mib(b: u64) -> String {
    format!("{} MiB", b >> 20)
}

fn describe(d: &DeviceInfo, default: Option<usize>) -> String {
    let mark = if Some(d.index) == default {
        " (default)"
    } else {
        ""
    };
    let usable = match d.missing_requirements() {
        None => "usable".to_string(),
        Some(m) => format!("NOT usable: lacks {m}"),
    };
    format!(
        "[{}] {}{mark}\n    type {}, driver {}, Vulkan {}\n    device-local memory {}, unified host-visible memory: {}\n    subgroup size {}, float atomic add: {}, max storage buffer range {}, max push constants {} B\n    buffer device address: {}, int64: {}, timestamps: {}\n    {usable}{}",
        d.index,
        d.name,
        d.kind,
        d.driver,
        d.api_version,
        mib(d.device_local_bytes),
        d.unified_memory,
        d.subgroup_size,
        if d.float_atomic_add { "yes" } else { "no (gradient kernels unavailable; use --backend cpu)" },
        mib(d.max_storage_buffer_range as u64),
        d.max_push_constants,
        d.buffer_device_address,
        d.shader_int64,
        d.timestamp_period_ns
            .map(|p| format!("{p} ns/tick"))
            .unwrap_or_else(|| "no".into()),
        if d.kind == DeviceKind::Cpu { " (CPU implementation, e.g. Mesa lavapipe)" } else { "" },
    )
}

/// Print the devices; fails only when the Vulkan loader itself is missing.
pub fn run() -> Result<()> {
    match list_devices() {
        Ok(devs) => {
            let default = crate::gpu::pick_default(&devs);
            if devs.is_empty() {
                println!("no Vulkan devices (install mesa-vulkan-drivers for lavapipe)");
            }
            for d in &devs {
                println!("{}", describe(d, default));
            }
        }
        Err(e) => println!("Vulkan unavailable: {e:#}"),
    }
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| m.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    println!(
        "[cpu] CPU backend (rayon): {} threads on {cpu}",
        rayon::current_num_threads()
    );
    Ok(())
}
