//! Memory estimates for flags that size allocations (`--batch`, `--res`, `--views`,
//! `--gt-spacing`, `--plenoxels-set res=…`, `--mesh-samples`, `--cases`): a command checks its
//! estimate against the memory this process may really use before allocating, so a too-large
//! value is a clear error rather than an out-of-memory abort.
//!
//! The memory a process may use is the least of the machine's `MemAvailable`, what its
//! address-space and data-segment limits (`ulimit -v`, `ulimit -d`) leave above what it already
//! maps, and what its cgroup's limit (v2 `memory.max`, v1 `memory.limit_in_bytes`) leaves above
//! the cgroup's usage.

use anyhow::{bail, Result};
use std::path::{Path, PathBuf};

/// Memory a new allocation may take, and the limit that sets it (named in messages).
#[derive(Clone, Debug, PartialEq)]
pub struct Available {
    pub bytes: u64,
    /// E.g. "MemAvailable in /proc/meminfo", "the address-space limit (ulimit -v)".
    pub source: String,
}

/// The memory this process may still allocate (the least of the limits in the module
/// documentation); `None` where none of them can be read.
pub fn available() -> Option<Available> {
    let meminfo = std::fs::read_to_string("/proc/meminfo").ok();
    let status = std::fs::read_to_string("/proc/self/status").ok();
    let mut limits = Vec::new();
    if let Some(b) = meminfo.as_deref().and_then(parse_mem_available) {
        limits.push(Available {
            bytes: b,
            source: "MemAvailable in /proc/meminfo".into(),
        });
    }
    for (resource, kind, status_key, flag) in rlimits() {
        let Some(limit) = rlimit(resource) else {
            continue;
        };
        let used = status
            .as_deref()
            .and_then(|s| status_kib(s, status_key))
            .unwrap_or(0);
        limits.push(Available {
            bytes: limit.saturating_sub(used),
            source: format!("the {kind} limit ({flag}) less the {status_key} this process uses"),
        });
    }
    if let Some(c) = cgroup_room() {
        limits.push(c);
    }
    limits.into_iter().min_by_key(|a| a.bytes)
}

/// Bytes of memory available to a new allocation (see [`available`]).
pub fn available_bytes() -> Option<u64> {
    available().map(|a| a.bytes)
}

fn parse_mem_available(meminfo: &str) -> Option<u64> {
    status_kib(meminfo, "MemAvailable")
}

/// A `Key:  N kB` line of `/proc/meminfo` or `/proc/self/status`, in bytes.
fn status_kib(text: &str, key: &str) -> Option<u64> {
    let line = text
        .lines()
        .find(|l| l.strip_prefix(key).is_some_and(|r| r.starts_with(':')))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// The resource limits that bound allocations: (resource, its name, the `/proc/self/status`
/// line of what counts against it, the shell flag that sets it).
#[cfg(unix)]
fn rlimits() -> [(libc::c_int, &'static str, &'static str, &'static str); 2] {
    [
        (
            libc::RLIMIT_AS as libc::c_int,
            "address-space",
            "VmSize",
            "ulimit -v",
        ),
        (
            libc::RLIMIT_DATA as libc::c_int,
            "data-segment",
            "VmData",
            "ulimit -d",
        ),
    ]
}

#[cfg(not(unix))]
fn rlimits() -> [(i32, &'static str, &'static str, &'static str); 0] {
    []
}

/// The soft limit of `resource` in bytes; `None` when unlimited or unreadable.
#[cfg(unix)]
fn rlimit(resource: libc::c_int) -> Option<u64> {
    let mut lim = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit writes the struct it is given; the resource ids come from libc.
    let ok = unsafe { libc::getrlimit(resource as _, &mut lim) } == 0;
    // `rlim_t` is 64-bit here but not on every Unix.
    #[allow(clippy::unnecessary_cast)]
    let limit = lim.rlim_cur as u64;
    (ok && lim.rlim_cur != libc::RLIM_INFINITY).then_some(limit)
}

#[cfg(not(unix))]
fn rlimit(_resource: i32) -> Option<u64> {
    None
}

/// What this process's memory cgroup still allows: its limit less its usage (v2 `memory.max`
/// and `memory.current`, v1 `memory.limit_in_bytes` and `memory.usage_in_bytes`), looked up
/// at the path `/proc/self/cgroup` names and, in a container, at the mount's root.
fn cgroup_room() -> Option<Available> {
    let own = std::fs::read_to_string("/proc/self/cgroup").unwrap_or_default();
    let root = Path::new("/sys/fs/cgroup");
    let mut dirs: Vec<(PathBuf, bool)> = Vec::new();
    for line in own.lines() {
        let mut parts = line.splitn(3, ':');
        let (Some(id), Some(ctrl), Some(path)) = (parts.next(), parts.next(), parts.next()) else {
            continue;
        };
        let rel = path.trim_start_matches('/');
        if id == "0" && ctrl.is_empty() {
            dirs.push((root.join(rel), true));
        } else if ctrl.split(',').any(|c| c == "memory") {
            dirs.push((root.join("memory").join(rel), false));
        }
    }
    dirs.push((root.to_path_buf(), true));
    dirs.push((root.join("memory"), false));
    let read = |p: PathBuf| -> Option<u64> { std::fs::read_to_string(p).ok()?.trim().parse().ok() };
    for (dir, v2) in dirs {
        let (limit, usage, name) = if v2 {
            ("memory.max", "memory.current", "cgroup v2 memory.max")
        } else {
            (
                "memory.limit_in_bytes",
                "memory.usage_in_bytes",
                "cgroup v1 memory.limit_in_bytes",
            )
        };
        // "max" (v2) does not parse: no limit here. v1 writes a huge number for none.
        let Some(limit) = read(dir.join(limit)).filter(|&l| l < 1 << 60) else {
            continue;
        };
        let usage = read(dir.join(usage)).unwrap_or(0);
        return Some(Available {
            bytes: limit.saturating_sub(usage),
            source: format!("the {name} less the cgroup's usage ({})", dir.display()),
        });
    }
    None
}

fn gib(b: f64) -> String {
    format!("{:.1} GiB", b / (1u64 << 30) as f64)
}

/// Refuse `what` when its estimated need `bytes` (a float, so products of large flags cannot
/// overflow) exceeds what is `available`; `None` (unknown) refuses only needs past the address
/// space.
pub fn check_fits(what: &str, bytes: f64, available: Option<&Available>) -> Result<()> {
    if bytes.is_nan() || bytes > u64::MAX as f64 / 2.0 {
        bail!("{what} would need about {bytes:.3e} bytes: far beyond any memory");
    }
    if let Some(avail) = available {
        if bytes > avail.bytes as f64 {
            bail!(
                "{what} would need about {} of memory, and {} is available ({}); use a smaller \
                 value",
                gib(bytes),
                gib(avail.bytes as f64),
                avail.source
            );
        }
    }
    Ok(())
}

/// Whether a copy of `bytes` leaves as much again of the memory this process may use (a
/// checkpoint copied to be written in the background must not push the run out of memory);
/// unknown availability counts as room.
pub fn room_for_copy(bytes: u64) -> bool {
    has_room(bytes, available_bytes())
}

fn has_room(bytes: u64, available: Option<u64>) -> bool {
    available.is_none_or(|a| bytes <= a / 2)
}

/// [`check_fits`] against the memory this process may use now.
pub fn ensure_fits(what: &str, bytes: f64) -> Result<()> {
    check_fits(what, bytes, available().as_ref())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_copy_needs_as_much_again_available() {
        assert!(has_room(1 << 20, Some(2 << 20)));
        assert!(!has_room((1 << 20) + 1, Some(2 << 20)));
        assert!(!has_room(u64::MAX, Some(u64::MAX)));
        assert!(has_room(u64::MAX, None));
    }

    #[test]
    fn estimates_past_available_memory_are_refused() {
        let info = "MemTotal: 100 kB\nMemFree: 10 kB\nMemAvailable:   2048 kB\n";
        assert_eq!(parse_mem_available(info), Some(2 << 20));
        assert_eq!(parse_mem_available("MemTotal: 1 kB\n"), None);
        assert_eq!(
            status_kib("VmSizeX: 1 kB\nVmSize: 3 kB\n", "VmSize"),
            Some(3072)
        );
        let two_mib = Available {
            bytes: 2 << 20,
            source: "ulimit -v".into(),
        };
        check_fits("x", 1e6, Some(&two_mib)).unwrap();
        let err = check_fits("--batch 4000000000", 3e6, Some(&two_mib)).unwrap_err();
        let err = format!("{err}");
        assert!(
            err.contains("--batch 4000000000") && err.contains("ulimit -v"),
            "{err}"
        );
        assert!(check_fits("x", 1e30, None).is_err());
        assert!(check_fits("x", f64::NAN, None).is_err());
        assert!(
            available_bytes().is_some_and(|b| b > 0),
            "Linux: MemAvailable readable"
        );
    }
}
