//! Parity of `glsl/trilerp_eval.comp` with `cpu::trilerp_eval`: value, gradient and weights,
//! compared after dividing by the case's largest corner magnitude (so the tolerance is relative
//! to the data's scale, also where the gradient cancels). Not bit-exact on lavapipe: Mesa 22.3
//! evaluates GLSL `fma()` as a multiply and an add (measured: its outputs equal an unfused twin
//! bit for bit), while the twin's `f32::mul_add` is fused, so outputs differ by about one ulp.

use super::{CheckRow, Compare};
use crate::gpu::Gpu;
use crate::kernels::trilerp_eval::{Push, INFO};
use anyhow::Result;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// Absolute tolerance on scale-normalised outputs.
pub const ABS: f64 = 1e-6;
/// Relative tolerance.
pub const REL: f64 = 1e-5;

/// `count` cases (8 corners, 3 coordinates each): corner scales from 1e-6 to 1e6, near-constant
/// cells, and p on the cell's corners, faces and midpoints as well as uniform in [0,1]³.
pub fn cases(count: usize, seed: u64) -> (Vec<f32>, Vec<f32>) {
    let mut rng = Pcg64::seed_from_u64(seed);
    let mut corners = Vec::with_capacity(8 * count);
    let mut points = Vec::with_capacity(3 * count);
    for i in 0..count {
        let scale = 10f32.powi(rng.random_range(-6..=6));
        let base: f32 = if i % 5 == 0 {
            rng.random_range(-1.0..1.0)
        } else {
            0.0
        };
        let spread = if i % 5 == 0 { 1e-4 } else { 1.0 };
        for _ in 0..8 {
            corners.push(scale * (base + spread * rng.random_range(-1.0f32..1.0)));
        }
        for _ in 0..3 {
            points.push(match i % 4 {
                0 => [0.0, 0.5, 1.0][rng.random_range(0..3)],
                _ => rng.random_range(0.0..=1.0),
            });
        }
    }
    (corners, points)
}

/// Runs the kernel over the cases; 12 outputs per case.
pub fn run_gpu(gpu: &Gpu, corners: &[f32], points: &[f32]) -> Result<Vec<f32>> {
    let n = corners.len() / 8;
    let c = gpu.upload(corners)?;
    let p = gpu.upload(points)?;
    let out = gpu.zeros::<f32>(12 * n)?;
    let push = Push {
        corners: c.address(),
        points: p.address(),
        out_: out.address(),
        n: n as u32,
        ..Default::default()
    };
    gpu.run_1d(&INFO, &push, n as u32)?;
    out.download()
}

/// 100k random and adversarial cases, GPU against the CPU twin.
pub fn check(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    let (corners, points) = cases(100_000, seed);
    let got = run_gpu(gpu, &corners, &points)?;
    let mut want = vec![0.0; got.len()];
    crate::cpu::trilerp_eval(&corners, &points, &mut want);
    let mut cmp = Compare::new(ABS, REL);
    const NAMES: [&str; 4] = ["value", "d/dx", "d/dy", "d/dz"];
    for (i, (g, w)) in got.chunks_exact(12).zip(want.chunks_exact(12)).enumerate() {
        let s = corners[8 * i..8 * i + 8]
            .iter()
            .fold(0f32, |m, c| m.max(c.abs()))
            .max(1e-30) as f64;
        for j in 0..12 {
            let (a, b) = if j < 4 {
                (g[j] as f64 / s, w[j] as f64 / s)
            } else {
                (g[j] as f64, w[j] as f64)
            };
            cmp.value(a, b, || {
                let what = if j < 4 {
                    NAMES[j].to_string()
                } else {
                    format!("w{}", j - 4)
                };
                format!("case {i} {what}")
            });
        }
    }
    let n = corners.len() / 8;
    Ok(cmp.row(
        INFO.name,
        n,
        "value and gradient / max|corner|; weights as is; ~1 ulp: lavapipe does not fuse fma()"
            .into(),
    ))
}
