//! Per-kernel device time, accumulated from the timestamp queries of every submitted batch and
//! printed by the global `--profile` flag.

use std::collections::BTreeMap;
use std::sync::Mutex;

/// Running totals per kernel: dispatch count and device nanoseconds.
#[derive(Default)]
pub struct Profile {
    totals: Mutex<BTreeMap<&'static str, (u64, f64)>>,
}

impl Profile {
    pub(super) fn add(&self, kernel: &'static str, ns: f64) {
        let mut t = self.totals.lock().unwrap();
        let e = t.entry(kernel).or_default();
        e.0 += 1;
        e.1 += ns;
    }

    /// (kernel, dispatches, total device ns), by kernel name.
    pub fn totals(&self) -> Vec<(&'static str, u64, f64)> {
        self.totals
            .lock()
            .unwrap()
            .iter()
            .map(|(k, (n, ns))| (*k, *n, *ns))
            .collect()
    }

    /// A printable table, or a line saying nothing ran on the device.
    pub fn report(&self) -> String {
        let rows = self.totals();
        if rows.is_empty() {
            return "profile: no kernel ran on the Vulkan device\n".into();
        }
        let total: f64 = rows.iter().map(|r| r.2).sum();
        let mut s = format!(
            "{:<24} {:>10} {:>12} {:>12} {:>7}\n",
            "kernel", "dispatches", "total ms", "mean µs", "share"
        );
        for (k, n, ns) in rows {
            s += &format!(
                "{k:<24} {n:>10} {:>12.3} {:>12.1} {:>6.1}%\n",
                ns / 1e6,
                ns / 1e3 / n as f64,
                100.0 * ns / total.max(1e-9)
            );
        }
        s
    }
}
