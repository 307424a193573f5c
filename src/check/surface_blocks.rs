//! Parity of `glsl/surface_live_cells.comp`, `glsl/surface_blocks.comp` and
//! `glsl/surface_block_radius.comp` (the stage-2 walks' skip structure: live-cell bits, block
//! level masks and empty radii) with
//! `cpu::surface_blocks::build_blocks`: exact equality of every word, on random
//! test scenes at sizes that are and are not 8k+1 vertices (n = 40, 24, 17, 9, 2), with 3 % and 60 %
//! of the vertices unallocated (whole blocks without an allocated vertex included), 5 and 8
//! levels, margins 0 and 0.05.

use super::surface_fwd::test_scene;
use super::{CheckRow, Compare};
use crate::cpu::surface_blocks::build_blocks;
use crate::gpu::Gpu;
use crate::math::surface_blocks::{alloc_box, complete_cells};
use crate::math::surface_blocks::{
    surf_blocks_per_axis, surf_live_words, SURF_BLOCK_SHIFT_CPU, SURF_BLOCK_SHIFT_VULKAN,
    SURF_MASK_BITS, SURF_RADIUS_SHIFT,
};
use crate::surface::skip::{record_skip_structure, SkipIo};
use anyhow::Result;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// Runs `surface_live_cells`, `surface_blocks` and `surface_block_radius` on the device: the skip
/// structure (live-cell words, then the `nb`³ block words, then the host's allocated box) and the
/// device time of all (ns).
pub fn build_blocks_gpu(
    gpu: &Gpu,
    n: u32,
    links: &[i32],
    delta: &[f32],
    levels: &[f32],
    margin: f32,
    shift: u32,
) -> Result<(Vec<u32>, f64)> {
    let nb = surf_blocks_per_axis(n, shift);
    let words = surf_live_words(n);
    let count = nb * nb * nb;
    let mut lv = levels.to_vec();
    lv.resize(8, 0.0);
    let cb = gpu.upload(&complete_cells(links, n))?;
    let lb = gpu.upload(links)?;
    let db = gpu.upload(if delta.is_empty() { &[0.0] } else { delta })?;
    let vb = gpu.upload(&lv)?;
    // The allocated box after the masks is written once per grid by the host (as VulkanSurface).
    let mut init = vec![0u32; (words + count) as usize];
    init.extend(alloc_box(links, n));
    let out = gpu.upload(&init)?;
    let scratch = gpu.zeros::<u32>(2 * count as usize)?;
    let mut b = gpu.batch()?;
    record_skip_structure(
        &mut b,
        &SkipIo {
            complete: cb.address(),
            links: lb.address(),
            delta: db.address(),
            levels: vb.address(),
            skip: out.address(),
            scratch: scratch.address(),
            n,
            n_levels: levels.len() as u32,
            shift,
        },
        margin,
    )?;
    let times = b.submit()?;
    Ok((
        out.download()?,
        times.kernel_ns("surface_live_cells")
            + times.kernel_ns("surface_blocks")
            + times.kernel_ns("surface_block_radius"),
    ))
}

/// The parity row of the block masks (`surface_blocks`).
pub fn check(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    compare(gpu, seed, Part::Masks)
}

/// The parity row of the empty radii (`surface_block_radius`).
pub fn check_radius(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    compare(gpu, seed, Part::Radii)
}

/// The parity row of the live-cell bits (`surface_live_cells`).
pub fn check_live(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    compare(gpu, seed, Part::Live)
}

/// What a row compares: the live-cell words, or the level masks or the empty radii of the block
/// words.
#[derive(Clone, Copy, PartialEq)]
enum Part {
    Live,
    Masks,
    Radii,
}

/// The skip structure built on the device and on the CPU for every case; `part`: what to compare
/// (exactly).
fn compare(gpu: &Gpu, seed: u64, part: Part) -> Result<CheckRow> {
    let mut cmp = Compare::new(0.0, 0.0);
    let mut rng = Pcg64::seed_from_u64(seed ^ 0xb10c_5eed);
    let mut cases = 0;
    let mut live = 0;
    let mut live_cells = 0;
    let (mut wide, mut widest) = (0, 0);
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
            // Both backends' block edges, 8 and 4 cells.
            for (levels, margin, shift) in [
                (sc.levels.clone(), 0.0f32, SURF_BLOCK_SHIFT_CPU),
                (sc.levels.clone(), 0.0f32, SURF_BLOCK_SHIFT_VULKAN),
                (
                    (0..8).map(|i| (i as f32 - 3.5) * 0.1).collect(),
                    0.05,
                    SURF_BLOCK_SHIFT_VULKAN,
                ),
            ] {
                let want = build_blocks(&sc.grid(), &levels, margin, shift)?;
                let (got, _) =
                    build_blocks_gpu(gpu, n, &sc.links, &sc.delta, &levels, margin, shift)?;
                let words = surf_live_words(n) as usize;
                if got.len() != want.len() {
                    cmp.failures += 1;
                    continue;
                }
                let nb = surf_blocks_per_axis(n, shift) as usize;
                let range = if part == Part::Live {
                    0..words
                } else {
                    words..words + nb * nb * nb
                };
                // The compared field of a word.
                let field = |w: u32| match part {
                    Part::Live => w,
                    Part::Masks => w & SURF_MASK_BITS,
                    Part::Radii => w >> SURF_RADIUS_SHIFT,
                };
                for i in range.clone() {
                    let (g, w) = (field(got[i]), field(want[i]));
                    cmp.value(g as f64, w as f64, || {
                        let what = ["live word", "block mask", "block radius"][part as usize];
                        format!(
                            "n {n} holes {holes} margin {margin} shift {shift} {what} {i}: gpu \
                             {g:#b} cpu {w:#b}"
                        )
                    });
                }
                live += want[range.clone()]
                    .iter()
                    .filter(|&&m| m & SURF_MASK_BITS != 0)
                    .count();
                let radii = want[range.clone()].iter().map(|&m| m >> SURF_RADIUS_SHIFT);
                wide += radii.clone().filter(|&r| r > 0).count();
                widest = widest.max(radii.max().unwrap_or(0));
                live_cells += want[..words]
                    .iter()
                    .map(|w| w.count_ones() as usize)
                    .sum::<usize>();
                cases += if part == Part::Live {
                    (n as usize).pow(3)
                } else {
                    range.len()
                };
            }
        }
    }
    Ok(match part {
        Part::Live => cmp.row(
            "surface_live_cells",
            cases,
            format!("live-cell bits exact; {live_cells} of {cases} cells live"),
        ),
        Part::Masks => cmp.row(
            "surface_blocks",
            cases,
            format!("masks exact; {live} of {cases} blocks live"),
        ),
        Part::Radii => cmp.row(
            "surface_block_radius",
            cases,
            format!(
                "empty radii exact; {} blocks without levels, {wide} of them with a radius ≥ 1 \
                 (largest {widest})",
                cases - live
            ),
        ),
    })
}
