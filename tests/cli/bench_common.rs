//! Checks shared by the `bench plenoxels|surface --json` tests: where a step's time goes.

use serde_json::Value;

/// The host phases every backend object reports under `host_ms` (ms per step).
const PHASES: [&str; 9] = [
    "sampling",
    "upload",
    "record",
    "submit",
    "wait",
    "readback",
    "compute",
    "bookkeeping",
    "other",
];

/// Checks backend object `o` (`vulkan`: kernels on the device, or `cpu`: the twins on the host)
/// of a bench's JSON line: `wall_ms_per_step`, `device_ms_total_per_step` and every phase of
/// `host_ms` finite and ≥ 0; the phases add up to the wall time, and the named ones (all but
/// `other`) cover at least 90 % of it — the spans are contiguous, so only the calls between them
/// are left over; the device time lies within the wall time, and on Vulkan the host waited for
/// it (`wait` > 0, no `compute`), on the CPU it is the twins' `compute` and nothing went through
/// a queue.
pub fn check_step_times(what: &str, o: &Value, vulkan: bool) {
    let f = |v: &Value| {
        let x = v
            .as_f64()
            .unwrap_or_else(|| panic!("{what}: not a number: {v} in {o}"));
        assert!(x.is_finite() && x >= 0.0, "{what}: {x} in {o}");
        x
    };
    let (wall, device) = (f(&o["wall_ms_per_step"]), f(&o["device_ms_total_per_step"]));
    let host = o["host_ms"]
        .as_object()
        .unwrap_or_else(|| panic!("{what}: no host_ms in {o}"));
    let mut keys: Vec<&str> = host.keys().map(String::as_str).collect();
    keys.sort();
    let mut phases = PHASES.to_vec();
    phases.sort();
    assert_eq!(keys, phases, "{what}");
    let ms = |k: &str| f(&host[k]);
    let total: f64 = PHASES.iter().map(|k| ms(k)).sum();
    let named = total - ms("other");
    assert!(wall > 0.0, "{what}: {o}");
    assert!(
        (total - wall).abs() <= 1e-9 * wall,
        "{what}: phases {total} ms, wall {wall} ms"
    );
    assert!(
        named <= wall * (1.0 + 1e-9) && named >= 0.9 * wall,
        "{what}: named phases {named} ms of {wall} ms"
    );
    assert!(
        device > 0.0 && device <= wall,
        "{what}: device {device} ms, wall {wall} ms"
    );
    if vulkan {
        // Sampling is recording the batch's draw (and on lavapipe, a CPU device, drawing its
        // keys: gpu::KeyDraw); the rays are written on the device.
        assert!(ms("sampling") > 0.0, "{what}: {o}");
        assert!(ms("wait") > 0.0 && ms("record") > 0.0, "{what}: {o}");
        assert_eq!(ms("compute"), 0.0, "{what}");
    } else {
        assert!(ms("sampling") > 0.0, "{what}: {o}");
        assert_eq!(ms("compute"), device, "{what}");
        for k in ["upload", "record", "submit", "wait", "readback"] {
            assert_eq!(ms(k), 0.0, "{what}: {k}");
        }
    }
}
