//! Parity of `glsl/loss_sum.comp` with `cpu::loss_sum`: exact equality (both add in the same
//! fixed order), on batch sizes around the workgroup's width, both record layouts the training
//! steps use, magnitudes from 1e-8 to 1e4, and records holding NaN and ±Inf.

use super::{CheckRow, Compare};
use crate::abi::consts::{LOSS_SUM_FIELDS, LOSS_SUM_THREADS};
use crate::cpu::loss_sum;
use crate::gpu::Gpu;
use crate::kernels::loss_sum::{Push, INFO};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// The `check-kernels` row.
pub fn check(gpu: &Gpu, seed: u64) -> anyhow::Result<CheckRow> {
    let mut rng = Pcg64::seed_from_u64(seed);
    let t = LOSS_SUM_THREADS as usize;
    // (rays, floats per record, fields summed, non-finite values planted)
    let cases = [
        (0, 4, 3, false),
        (1, 4, 3, false),
        (t - 1, 1, 1, false),
        (t, 4, 3, false),
        (t + 1, 4, 4, false),
        (4096, 4, 3, false),
        (4096, 1, 1, false),
        (10_007, 4, 3, false),
        (4096, 4, 3, true),
    ];
    let mut cmp = Compare::new(0.0, 0.0);
    let mut b = gpu.batch()?;
    let mut inputs = Vec::new();
    let out = gpu.zeros::<f32>(cases.len() * LOSS_SUM_FIELDS as usize)?;
    for (i, &(n, stride, fields, bad)) in cases.iter().enumerate() {
        let mut src: Vec<f32> = (0..n * stride)
            .map(|_| rng.random_range(0.0f32..1.0) * 10f32.powi(rng.random_range(-8..5)))
            .collect();
        if bad {
            src[stride * 17] = f32::NAN;
            src[stride * 900 + 1] = f32::INFINITY;
            src[stride * 901 + 2] = f32::NEG_INFINITY;
        }
        // A buffer of at least one word, so that n = 0 has an address too.
        let buf = gpu.upload(&if src.is_empty() {
            vec![0.0]
        } else {
            src.clone()
        })?;
        b.dispatch(
            &INFO,
            &Push {
                src: buf.address(),
                dst: out.address() + 4 * (i as u64 * LOSS_SUM_FIELDS as u64),
                n: n as u32,
                stride: stride as u32,
                fields: fields as u32,
                ..Default::default()
            },
            [1, 1, 1],
        )?;
        inputs.push((src, n, stride, fields, buf));
    }
    b.submit()?;
    let got: Vec<f32> = out.download()?;
    for (i, (src, n, stride, fields, _)) in inputs.iter().enumerate() {
        let want = loss_sum(src, *n, *stride, *fields);
        for f in 0..*fields {
            let g = got[i * LOSS_SUM_FIELDS as usize + f];
            cmp.value(g as f64, want[f] as f64, || {
                format!("case {i} ({n} rays) field {f}")
            });
        }
    }
    Ok(cmp.row(
        INFO.name,
        cases.len(),
        "batches of 0 to 10007 rays, NaN/±Inf records; exact".into(),
    ))
}
