//! Parity of `glsl/fill_pattern.comp` with `cpu::fill_pattern`: exact equality.

use super::{CheckRow, Compare};
use crate::gpu::Gpu;
use crate::kernels::fill_pattern::{Push, INFO};

/// Fill `n` u32 on the device and on the CPU and compare every element. Returns the row.
pub fn check_n(gpu: &Gpu, seed: u64, n: usize) -> anyhow::Result<CheckRow> {
    let buf = gpu.zeros::<u32>(n)?;
    let seed = seed as u32;
    gpu.run_1d(
        &INFO,
        &Push {
            dst: buf.address(),
            n: n as u32,
            seed,
        },
        n as u32,
    )?;
    let got: Vec<u32> = buf.download()?;
    let mut want = vec![0u32; n];
    crate::cpu::fill_pattern(&mut want, seed);
    let mut cmp = Compare::new(0.0, 0.0);
    let mismatches = got.iter().zip(&want).filter(|(g, w)| g != w).count();
    let first = got.iter().zip(&want).position(|(g, w)| g != w);
    cmp.compared = n;
    cmp.failures = mismatches;
    if let Some(i) = first {
        cmp.first_failure = Some(format!("element {i}: gpu {} cpu {}", got[i], want[i]));
    }
    Ok(cmp.row(INFO.name, n, format!("{} MiB buffer, exact", (4 * n) >> 20)))
}

/// The `check-kernels` row: a 1 Mi-element buffer.
pub fn check(gpu: &Gpu, seed: u64) -> anyhow::Result<CheckRow> {
    check_n(gpu, seed, 1 << 20)
}
