//! Memory estimates for flags that size allocations (`--batch`, `--res`, `--views`,
//! `--gt-spacing`): a command checks its estimate against the memory available before
//! allocating, so a too-large value is a clear error rather than an out-of-memory abort.

use anyhow::{bail, Result};

/// Bytes of memory available to a new allocation: `MemAvailable` from `/proc/meminfo` (Linux);
/// `None` where that cannot be read.
pub fn available_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    parse_mem_available(&text)
}

fn parse_mem_available(meminfo: &str) -> Option<u64> {
    let line = meminfo.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

fn gib(b: f64) -> String {
    format!("{:.1} GiB", b / (1u64 << 30) as f64)
}

/// Refuse `what` when its estimated need `bytes` (a float, so products of large flags cannot
/// overflow) exceeds `available` bytes; `available = None` (unknown) refuses only needs past
/// the address space.
pub fn check_fits(what: &str, bytes: f64, available: Option<u64>) -> Result<()> {
    if bytes.is_nan() || bytes > u64::MAX as f64 / 2.0 {
        bail!("{what} would need about {bytes:.3e} bytes: far beyond any memory");
    }
    if let Some(avail) = available {
        if bytes > avail as f64 {
            bail!(
                "{what} would need about {} of memory, and {} is available (MemAvailable in \
                 /proc/meminfo); use a smaller value",
                gib(bytes),
                gib(avail as f64)
            );
        }
    }
    Ok(())
}

/// Whether a copy of `bytes` leaves as much again of this machine's available memory (a
/// checkpoint copied to be written in the background must not push the run out of memory);
/// unknown availability counts as room.
pub fn room_for_copy(bytes: u64) -> bool {
    has_room(bytes, available_bytes())
}

fn has_room(bytes: u64, available: Option<u64>) -> bool {
    available.is_none_or(|a| bytes <= a / 2)
}

/// [`check_fits`] against this machine's available memory.
pub fn ensure_fits(what: &str, bytes: f64) -> Result<()> {
    check_fits(what, bytes, available_bytes())
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
        check_fits("x", 1e6, Some(2 << 20)).unwrap();
        let err = check_fits("--batch 4000000000", 3e6, Some(2 << 20)).unwrap_err();
        assert!(format!("{err}").contains("--batch 4000000000"), "{err}");
        assert!(check_fits("x", 1e30, None).is_err());
        assert!(check_fits("x", f64::NAN, None).is_err());
        assert!(
            available_bytes().is_some_and(|b| b > 0),
            "Linux: MemAvailable readable"
        );
    }
}
