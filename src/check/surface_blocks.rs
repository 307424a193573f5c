//! Parity of `glsl/surface_blocks.comp` (block level masks for the stage-2 walk's empty-space
//! skipping) with `cpu::surface_blocks::build_blocks`: exact equality of every mask, on random
//! test scenes at sizes that are and are not 8k+1 vertices (n = 40, 24, 17, 9, 2), with 3 % and 60 %
//! of the vertices unallocated (whole blocks without an allocated vertex included), 5 and 8
//! levels, margins 0 and 0.05.

use super::surface_fwd::test_scene;
use super::{CheckRow, Compare};
use crate::cpu::surface_blocks::build_blocks;
use crate::gpu::Gpu;
use crate::kernels::surface_blocks::{Push, INFO};
use anyhow::Result;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// Runs `surface_blocks` on the device: the masks (`nb`³) and the device time (ns).
pub fn build_blocks_gpu(
    gpu: &Gpu,
    n: u32,
    links: &[i32],
    delta: &[f32],
    levels: &[f32],
    margin: f32,
) -> Result<(Vec<u32>, f64)> {
    let nb = crate::math::surface_blocks::surf_blocks_per_axis(n);
    let count = nb * nb * nb;
    let mut lv = levels.to_vec();
    lv.resize(8, 0.0);
    let lb = gpu.upload(links)?;
    let db = gpu.upload(if delta.is_empty() { &[0.0] } else { delta })?;
    let vb = gpu.upload(&lv)?;
    let out = gpu.zeros::<u32>(count as usize)?;
    let times = gpu.run_1d(
        &INFO,
        &Push {
            links: lb.address(),
            delta: db.address(),
            levels: vb.address(),
            blocks: out.address(),
            n,
            n_levels: levels.len() as u32,
            margin,
            ..Default::default()
        },
        count,
    )?;
    Ok((out.download()?, times.kernel_ns("surface_blocks")))
}

/// The parity row.
pub fn check(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    let mut cmp = Compare::new(0.0, 0.0);
    let mut rng = Pcg64::seed_from_u64(seed ^ 0xb10c_5eed);
    let mut cases = 0;
    let mut live = 0;
    for (k, n) in [40u32, 24, 17, 9, 2].into_iter().enumerate() {
        for holes in [0.0f32, 0.6] {
            let mut sc = test_scene(seed + k as u64, n);
            if holes > 0.0 {
                for l in sc.links.iter_mut() {
                    if rng.random::<f32>() < holes {
                        *l = -1;
                    }
                }
                // One whole corner block without any allocated vertex.
                for x in 0..n.min(9) {
                    for y in 0..n.min(9) {
                        for z in 0..n.min(9) {
                            sc.links[((x * n + y) * n + z) as usize] = -1;
                        }
                    }
                }
            }
            for (levels, margin) in [
                (sc.levels.clone(), 0.0f32),
                ((0..8).map(|i| (i as f32 - 3.5) * 0.1).collect(), 0.05),
            ] {
                let want = build_blocks(&sc.grid(), &levels, margin)?;
                let (got, _) = build_blocks_gpu(gpu, n, &sc.links, &sc.delta, &levels, margin)?;
                for (i, (g, w)) in got.iter().zip(&want).enumerate() {
                    cmp.value(*g as f64, *w as f64, || {
                        format!(
                            "n {n} holes {holes} margin {margin} block {i}: gpu {g:#b} cpu {w:#b}"
                        )
                    });
                }
                if got.len() != want.len() {
                    cmp.failures += 1;
                }
                live += want.iter().filter(|&&m| m != 0).count();
                cases += want.len();
            }
        }
    }
    Ok(cmp.row(
        "surface_blocks",
        cases,
        format!("masks exact; {live} of {cases} blocks live"),
    ))
}
