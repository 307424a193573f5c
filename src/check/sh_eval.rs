//! Parity of `glsl/sh_eval.comp` with `cpu::sh_eval`: the 9 basis values and the RGB colour.
//! About one ulp apart on lavapipe, which evaluates `fma()` unfused (see `check::trilerp_eval`).

use super::{CheckRow, Compare};
use crate::gpu::Gpu;
use crate::kernels::sh_eval::{Push, INFO};
use anyhow::Result;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// Absolute tolerance.
pub const ABS: f64 = 1e-6;
/// Relative tolerance.
pub const REL: f64 = 1e-5;

/// `count` cases: unit directions (uniform, plus the ±axes and diagonals) and 27 coefficients in
/// [−1, 1] (every third case scaled to drive channels below zero, where the clamp acts).
pub fn cases(count: usize, seed: u64) -> (Vec<f32>, Vec<f32>) {
    let mut rng = Pcg64::seed_from_u64(seed);
    let mut dirs = Vec::with_capacity(3 * count);
    let mut coefs = Vec::with_capacity(27 * count);
    let special: [[f64; 3]; 8] = [
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
        [1.0, 1.0, 1.0],
        [-1.0, 1.0, -1.0],
    ];
    for i in 0..count {
        let v = if i % 10 == 0 {
            special[rng.random_range(0..special.len())]
        } else {
            loop {
                let v: [f64; 3] = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
                let l2: f64 = v.iter().map(|x| x * x).sum();
                if l2 > 1e-4 && l2 <= 1.0 {
                    break v;
                }
            }
        };
        let l = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        dirs.extend(v.iter().map(|x| (x / l) as f32));
        let s = if i % 3 == 0 { 4.0 } else { 1.0 };
        coefs.extend((0..27).map(|_| s * rng.random_range(-1.0f32..1.0)));
    }
    (dirs, coefs)
}

/// Runs the kernel over the cases; 12 outputs per case (Y_0..Y_8, R, G, B).
pub fn run_gpu(gpu: &Gpu, dirs: &[f32], coefs: &[f32]) -> Result<Vec<f32>> {
    let n = dirs.len() / 3;
    let d = gpu.upload(dirs)?;
    let c = gpu.upload(coefs)?;
    let out = gpu.zeros::<f32>(12 * n)?;
    let push = Push {
        dirs: d.address(),
        coefs: c.address(),
        out_: out.address(),
        n: n as u32,
        ..Default::default()
    };
    gpu.run_1d(&INFO, &push, n as u32)?;
    out.download()
}

/// 100k cases, GPU against the CPU twin.
pub fn check(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    let (dirs, coefs) = cases(100_000, seed);
    let got = run_gpu(gpu, &dirs, &coefs)?;
    let mut want = vec![0.0; got.len()];
    crate::cpu::sh_eval(&dirs, &coefs, &mut want);
    let mut cmp = Compare::new(ABS, REL);
    for (i, (g, w)) in got.chunks_exact(12).zip(want.chunks_exact(12)).enumerate() {
        for j in 0..12 {
            cmp.value(g[j] as f64, w[j] as f64, || {
                let what = if j < 9 {
                    format!("Y{j}")
                } else {
                    ["R", "G", "B"][j - 9].to_string()
                };
                format!("case {i} {what}")
            });
        }
    }
    let n = dirs.len() / 3;
    Ok(cmp.row(
        INFO.name,
        n,
        "9 basis values and RGB; ~1 ulp: lavapipe does not fuse fma()".into(),
    ))
}
