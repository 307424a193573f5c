//! Parity of the stage-1 kernels (occupancy, plenoxel_fwd, plenoxel_train, plenoxel_weights,
//! rmsprop, tv) with their CPU twins, on a small random grid with unallocated regions, empty
//! blocks and a dense blob, and on random plus adversarial rays (axis-aligned, starting inside
//! the box, grazing, missing); the render and training passes composite on [`TEST_BACKGROUND`]
//! (learned in training, so its gradient is compared too). Also `background_step`.

use super::{background_msi, grad_outliers, rel_l2, CheckRow, Compare, TEST_BACKGROUND};
use crate::abi::buffers::StepHeader;
use crate::abi::buffers::{Background, BackgroundSpheres};
use crate::abi::consts::TOUCH_ALL;
use crate::abi::regularisers::TvChunk;
use crate::abi::step::{step_record, STEP_FLAGS};
use crate::abi::train::RmsProp;
use crate::cpu::background_step::background_step;
use crate::cpu::occupancy;
use crate::cpu::optim_args::optim_args;
use crate::cpu::{rmsprop_sparse, tv, PlenoxelsOptimArrays};
use crate::gpu::{record_optim_args, record_tv, Gpu, GpuBuffer};
use crate::grid::{Grid, SH_DIM};
use crate::kernels;
use crate::math::background_msi::SphereTable;
use crate::math::plenoxel::{PlenoxelCounts, OCC_SHIFT};
use crate::plenoxel::{CpuPlenoxels, PlenoxelsBackend, VulkanPlenoxels};
use crate::stage::StageBackend;
use anyhow::Result;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// Stop threshold of the checks: the trainer's default.
const STOP: f32 = 1e-4;

/// A random test grid (res³, blob of density plus noise, a slab of thin fog, some vertices
/// unallocated, random SH),
/// `n_rays` rays (6 floats) and targets (3 floats).
pub fn test_scene(seed: u64, res: u32, n_rays: usize) -> (Grid, Vec<f32>, Vec<f32>) {
    let mut rng = Pcg64::seed_from_u64(seed);
    let mut g = Grid::sphere(res, [0.0; 3], [1.0; 3], 0.95, 0.0);
    let c: [f32; 3] = std::array::from_fn(|_| rng.random_range(-0.3..0.3));
    for s in 0..g.slots() {
        let l = g.links[s];
        if l < 0 {
            continue;
        }
        let v = g.vertex(s);
        let w = g.grid_to_world(v.map(|x| x as f32));
        let r2: f32 = (0..3).map(|i| (w[i] - c[i]).powi(2)).sum();
        // A blob of radius ~0.35; outside it σ ≤ 0 so whole occupancy blocks are empty.
        g.density[l as usize] = if w[2] < -0.3 {
            // Thin fog: rays through it shade more samples than plenoxel_train replays.
            0.5 + rng.random_range(-0.1..0.1)
        } else {
            60.0 * (-r2 / 0.06).exp() - 3.0 + rng.random_range(-1.0..1.0)
        };
        for k in 0..SH_DIM {
            g.sh[l as usize * SH_DIM + k] = rng.random_range(-0.4..0.4);
        }
    }
    // Punch holes: unallocate a few vertices inside the blob.
    let keep: Vec<bool> = (0..g.slots()).map(|_| rng.random::<f32>() > 0.03).collect();
    g.retain(&keep);
    let mut rays = Vec::with_capacity(6 * n_rays);
    for r in 0..n_rays {
        let (o, d): ([f32; 3], [f32; 3]) = match r % 10 {
            // Axis-aligned through the blob.
            0 => {
                let a = r / 10 % 3;
                let mut o = [
                    rng.random_range(-0.4..0.4),
                    rng.random_range(-0.4..0.4),
                    rng.random_range(-0.4..0.4),
                ];
                o[a] = -2.0;
                let mut d = [0.0; 3];
                d[a] = 1.0;
                (o, d)
            }
            // Starting inside the box.
            1 => {
                let o = std::array::from_fn(|_| rng.random_range(-0.5..0.5));
                (
                    o,
                    unit(std::array::from_fn(|_| rng.random_range(-1.0..1.0))),
                )
            }
            // Missing the box entirely.
            2 => ([3.0, 3.0, 3.0], unit([1.0, 0.2, 0.1])),
            // Along the fog slab.
            3 => (
                [
                    -2.0,
                    rng.random_range(-0.5..0.5),
                    rng.random_range(-0.8..-0.4),
                ],
                unit([
                    1.0,
                    rng.random_range(-0.2..0.2),
                    rng.random_range(-0.05..0.05),
                ]),
            ),
            // From a sphere of radius 2.5 at random points of the box.
            _ => {
                let o = unit(std::array::from_fn(|_| rng.random_range(-1.0..1.0))).map(|x| 2.5 * x);
                let at: [f32; 3] = std::array::from_fn(|_| rng.random_range(-0.7..0.7));
                (o, unit(std::array::from_fn(|i| at[i] - o[i])))
            }
        };
        rays.extend_from_slice(&o);
        rays.extend_from_slice(&d);
    }
    let targets = (0..3 * n_rays)
        .map(|_| rng.random_range(0.0..1.0))
        .collect();
    (g, rays, targets)
}

fn unit(v: [f32; 3]) -> [f32; 3] {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    v.map(|x| x / l)
}

fn counts_note(g: PlenoxelCounts, c: PlenoxelCounts) -> String {
    format!("gpu {g:?} cpu {c:?}")
}

/// The counters both backends share within 0.1 % + 2: samples shaded, samples walked past
/// (evaluated empty or skipped: how those split follows each backend's occupancy blocks,
/// `OCC_SHIFT` and `OCC_SHIFT_CPU`) and atomic adds.
fn counts_close(g: PlenoxelCounts, c: PlenoxelCounts) -> bool {
    let shared = |x: PlenoxelCounts| [x.shaded, x.empty + x.skipped, x.atomic_adds];
    (shared(g).into_iter().zip(shared(c)))
        .all(|(g, c)| (g as f64 - c as f64).abs() <= 1e-3 * c as f64 + 2.0)
}

pub fn check_occupancy(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    let (g, _, _) = test_scene(seed, 40, 0);
    let want = occupancy::occupancy(&g.links, &g.density, g.res, OCC_SHIFT);
    let links = gpu.upload(&g.links)?;
    let density = gpu.upload(&g.density)?;
    let occ = gpu.zeros::<u32>(want.len())?;
    gpu.run_1d(
        &kernels::occupancy::INFO,
        &kernels::occupancy::Push {
            links: links.address(),
            density: density.address(),
            occ: occ.address(),
            res: g.res,
            ..Default::default()
        },
        want.len() as u32,
    )?;
    let got: Vec<u32> = occ.download()?;
    let mut cmp = Compare::new(0.0, 0.0);
    for (i, (&a, &b)) in got.iter().zip(&want).enumerate() {
        cmp.value(a as f64, b as f64, || format!("block {i}"));
    }
    let empty = want.iter().filter(|&&o| o == 0).count();
    Ok(cmp.row(
        "occupancy",
        want.len(),
        format!("exact; {empty} of {} blocks empty", want.len()),
    ))
}

/// The two backends on `g`, composited on [`TEST_BACKGROUND`] (`learn`: learned), in front of
/// `spheres` (learned with it) when given.
fn backends(
    gpu: &Gpu,
    g: Grid,
    learn: bool,
    spheres: Option<&SphereTable>,
) -> Result<(CpuPlenoxels, VulkanPlenoxels)> {
    let bg = Background::new(TEST_BACKGROUND, learn);
    let spheres = spheres.map(|s| SphereTable {
        shape: BackgroundSpheres {
            learn: u32::from(learn),
            ..s.shape
        },
        ..s.clone()
    });
    let mut cpu = CpuPlenoxels::new(g.clone());
    cpu.set_background(bg)?;
    cpu.set_spheres(spheres.clone())?;
    let mut vk = VulkanPlenoxels::new(gpu, g)?;
    vk.set_background(bg)?;
    vk.set_spheres(spheres)?;
    Ok((cpu, vk))
}

pub fn check_fwd(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    fwd_row(gpu, seed, None)
}

/// `plenoxel_fwd` with spheres behind the grid (`background_msi::test_spheres`).
pub fn check_fwd_spheres(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    fwd_row(gpu, seed, Some(&background_msi::test_spheres(seed)))
}

/// The render row; with spheres, the tolerance adds their bound (`background_msi::abs_bound`).
fn fwd_row(gpu: &Gpu, seed: u64, spheres: Option<&SphereTable>) -> Result<CheckRow> {
    let (g, rays, _) = test_scene(seed, 40, 4000);
    let (mut cpu, mut vk) = backends(gpu, g, false, spheres)?;
    let (want, wc) = cpu.render(&rays, STOP)?;
    let (got, gc) = vk.render(&rays, STOP)?;
    let mut cmp = Compare::new(2e-5 + spheres.map_or(0.0, background_msi::abs_bound), 2e-4);
    for (i, (&a, &b)) in got.iter().zip(&want).enumerate() {
        cmp.value(a as f64, b as f64, || {
            format!("ray {} channel {}", i / 3, i % 3)
        });
    }
    // Sample counts may differ only where exp() rounding flips an early-termination test.
    if !counts_close(gc, wc) {
        cmp.failures += 1;
        cmp.first_failure.get_or_insert_with(|| counts_note(gc, wc));
    }
    let name = if spheres.is_some() {
        "plenoxel_fwd_spheres"
    } else {
        "plenoxel_fwd"
    };
    Ok(cmp.row(name, rays.len() / 6, counts_note(gc, wc)))
}

pub fn check_train(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    train_row(gpu, seed, None)
}

/// `plenoxel_train` with learned spheres behind the grid: their gradient compared too.
pub fn check_train_spheres(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    train_row(gpu, seed, Some(&background_msi::test_spheres(seed)))
}

/// The sparsity weight of the row without spheres; the row fails if the term changes the twin's
/// dσ by less than 1 % (relative L2), so that it stays tested.
const TRAIN_SPARSITY: f32 = 1e-6;

fn train_row(gpu: &Gpu, seed: u64, spheres: Option<&SphereTable>) -> Result<CheckRow> {
    let (g, rays, targets) = test_scene(seed, 40, 4000);
    let (mut cpu, mut vk) = backends(gpu, g, true, spheres)?;
    // The row with spheres keeps the sparsity term off, so both branches of the kernel run.
    let sparsity = if spheres.is_some() {
        0.0
    } else {
        TRAIN_SPARSITY
    };
    let want = cpu.gradients(&rays, &targets, STOP, sparsity)?;
    let got = vk.gradients(&rays, &targets, STOP, sparsity)?;
    let sparsity_share = if sparsity > 0.0 {
        rel_l2(
            &cpu.gradients(&rays, &targets, STOP, 0.0)?.density,
            &want.density,
        )
    } else {
        0.0
    };
    // Per-ray losses elementwise; atomically accumulated gradients by aggregate measures, and
    // elementwise against the largest magnitude (summation order differs run to run). Spheres
    // add their bound on B times the loss's slope in B: Σ_ch 2·|C − target| ≤ 3·2·1.4 < 9.
    let sphere_bound = spheres.map_or(0.0, background_msi::abs_bound);
    let mut cmp = Compare::new(1e-5 + 9.0 * sphere_bound, 1e-3);
    for (i, (&a, &b)) in got.ray_loss.iter().zip(&want.ray_loss).enumerate() {
        cmp.value(a as f64, b as f64, || format!("ray {i} loss"));
    }
    let (gc, wc) = (got.counts, want.counts);
    if !counts_close(gc, wc) {
        cmp.failures += 1;
        cmp.first_failure.get_or_insert_with(|| counts_note(gc, wc));
    }
    let mut worst = 0.0f64;
    for (name, a, b) in [
        ("dσ", &got.density, &want.density),
        ("dSH", &got.sh, &want.sh),
        ("d(sphere texels)", &got.spheres, &want.spheres),
    ] {
        if spheres.is_none() && b.is_empty() && a.is_empty() {
            continue;
        }
        let e = rel_l2(a, b);
        worst = worst.max(e);
        let bad = grad_outliers(a, b);
        if e > 1e-4 || bad > b.len() / 1000 {
            cmp.failures += 1;
            cmp.first_failure
                .get_or_insert_with(|| format!("{name}: rel L2 {e:.2e}, {bad} elements off"));
        }
    }
    // dL/dbg: a sum over the rays of dL/dC·T (subgroup sums and atomics against the twin's
    // sequential sum), as close as the per-ray terms.
    let e_bg = rel_l2(&got.background, &want.background);
    if e_bg > 1e-4 || want.background == [0.0; 3] {
        cmp.failures += 1;
        cmp.first_failure.get_or_insert_with(|| {
            format!(
                "dbg: rel L2 {e_bg:.2e}: gpu {:?} cpu {:?}",
                got.background, want.background
            )
        });
    }
    let reached = want.spheres.iter().filter(|&&g| g != 0.0).count();
    if spheres.is_some() && reached < want.spheres.len() / 4 {
        cmp.failures += 1;
        cmp.first_failure.get_or_insert_with(|| {
            format!(
                "only {reached} of {} sphere values reached",
                want.spheres.len()
            )
        });
    }
    if sparsity > 0.0 && sparsity_share < 0.01 {
        cmp.failures += 1;
        cmp.first_failure
            .get_or_insert_with(|| format!("sparsity changes dσ by {sparsity_share:.1e} only"));
    }
    let note = format!(
        "sparsity {sparsity:e} (its share of dσ {sparsity_share:.2}); grad rel L2 {worst:.1e} \
         (≤ 1e-4; elementwise |Δ| ≤ 1e-4·max|g| + 1e-3·|g| for all but 0.1%), dbg rel L2 \
         {e_bg:.1e} (≤ 1e-4); {}{}",
        counts_note(got.counts, want.counts),
        if spheres.is_some() {
            format!(
                "; {reached} of {} sphere values with a gradient",
                want.spheres.len()
            )
        } else {
            String::new()
        }
    );
    let name = if spheres.is_some() {
        "plenoxel_train_spheres"
    } else {
        "plenoxel_train"
    };
    Ok(cmp.row(name, rays.len() / 6, note))
}

pub fn check_weights(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    let (g, rays, _) = test_scene(seed, 40, 4000);
    let want = CpuPlenoxels::new(g.clone()).max_weights(&rays, 0.2)?;
    let got = VulkanPlenoxels::new(gpu, g)?.max_weights(&rays, 0.2)?;
    let mut cmp = Compare::new(1e-6, 1e-4);
    for (i, (&a, &b)) in got.iter().zip(&want).enumerate() {
        cmp.value(a as f64, b as f64, || format!("vertex {i}"));
    }
    Ok(cmp.row("plenoxel_weights", rays.len() / 6, "T-stop 0.2".into()))
}

/// A step buffer (glsl/lib/step.glsl) for `n` vertices with the given vertices touched.
fn step_buffer(n: usize, touched: &[usize]) -> Vec<u32> {
    let touched: Vec<(usize, u32)> = touched.iter().map(|&t| (t, TOUCH_ALL)).collect();
    step_record(n, &touched)
}

pub fn check_optim_args(gpu: &Gpu, _seed: u64) -> Result<CheckRow> {
    let mut cmp = Compare::new(0.0, 0.0);
    let counts = [
        0u32,
        1,
        63,
        64,
        65,
        100_000,
        64 * 32768,
        64 * 32768 + 1,
        5_000_000,
    ];
    for &count in &counts {
        let sb = gpu.upload(&[StepHeader {
            count,
            ..Default::default()
        }])?;
        let args = gpu.zeros::<u32>(3)?;
        gpu.run_1d(
            &kernels::optim_args::INFO,
            &kernels::optim_args::Push {
                step: sb.address(),
                args: args.address(),
            },
            1,
        )?;
        let got: Vec<u32> = args.download()?;
        for (i, (&g, &w)) in got.iter().zip(&optim_args(count)).enumerate() {
            cmp.value(g as f64, w as f64, || format!("count {count} arg {i}"));
        }
    }
    Ok(cmp.row(
        "optim_args",
        counts.len(),
        "exact; 0, group edges, multi-row".into(),
    ))
}

pub fn check_rmsprop(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    let mut rng = Pcg64::seed_from_u64(seed);
    let n = 20_000;
    let mut vals = |len: usize, lo: f32, hi: f32| -> Vec<f32> {
        (0..len).map(|_| rng.random_range(lo..hi)).collect()
    };
    let (mut density, mut sh) = (vals(n, -5.0, 5.0), vals(n * SH_DIM, -1.0, 1.0));
    let mut state_density = vals(n, 0.0, 2.0);
    let mut state_sh = vals(n * SH_DIM, 0.0, 2.0);
    let mut grad_density = vals(n, -1.0, 1.0);
    let mut grad_sh = vals(n * SH_DIM, -1.0, 1.0);
    // Fresh state (r = 0) on a fifth, zero gradients on a seventh, 1e-8..1e4 magnitudes.
    for i in 0..grad_sh.len() {
        if i % 5 == 0 {
            state_sh[i] = 0.0;
        }
        if i % 7 == 0 {
            grad_sh[i] = 0.0;
        }
        grad_sh[i] *= 10f32.powi((i % 13) as i32 - 8);
    }
    for i in (0..n).step_by(5) {
        state_density[i] = 0.0;
    }
    // Two thirds of the vertices touched, in scrambled order.
    let mut touched_list: Vec<usize> = (0..n).filter(|v| v % 3 != 0).collect();
    touched_list.reverse();
    let mut flags = vec![0u32; n];
    touched_list.iter().for_each(|&v| flags[v] = 1);
    let bufs: Vec<GpuBuffer> = [
        &density,
        &sh,
        &grad_density,
        &grad_sh,
        &state_density,
        &state_sh,
    ]
    .iter()
    .map(|v| gpu.upload(v))
    .collect::<Result<_>>()?;
    let step = gpu.upload(&step_buffer(n, &touched_list))?;
    let args = gpu.zeros::<u32>(3)?;
    let h = RmsProp {
        lr_sigma: 0.3,
        lr_sh: 0.01,
        beta: 0.95,
        eps: 1e-8,
    };
    let mut b = gpu.batch()?;
    record_optim_args(&mut b, &step, &args)?;
    b.dispatch_indirect(
        &kernels::rmsprop_sparse::INFO,
        &kernels::rmsprop_sparse::Push {
            density: bufs[0].address(),
            sh: bufs[1].address(),
            grad_density: bufs[2].address(),
            grad_sh: bufs[3].address(),
            state_density: bufs[4].address(),
            state_sh: bufs[5].address(),
            step: step.address(),
            lr_sigma: h.lr_sigma,
            lr_sh: h.lr_sh,
            beta: h.beta,
            eps: h.eps,
        },
        &args,
    )?;
    b.submit()?;
    rmsprop_sparse(
        PlenoxelsOptimArrays {
            density: &mut density,
            sh: &mut sh,
            grad_density: &mut grad_density,
            grad_sh: &mut grad_sh,
            state_density: &mut state_density,
            state_sh: &mut state_sh,
        },
        &mut flags,
        &h,
    );
    let mut cmp = Compare::new(1e-6, 1e-5);
    let names = [
        "density",
        "sh",
        "grad_density",
        "grad_sh",
        "state_density",
        "state_sh",
    ];
    let want = [
        &density,
        &sh,
        &grad_density,
        &grad_sh,
        &state_density,
        &state_sh,
    ];
    for ((buf, w), name) in bufs.iter().zip(want).zip(names) {
        let got: Vec<f32> = buf.download()?;
        for (i, (&a, &b)) in got.iter().zip(w.iter()).enumerate() {
            cmp.value(a as f64, b as f64, || format!("{name}[{i}]"));
        }
    }
    let got_flags: Vec<u32> = step.download_range(STEP_FLAGS, n)?;
    for (i, (&a, &b)) in got_flags.iter().zip(&flags).enumerate() {
        cmp.value(a as f64, b as f64, || format!("touched flag {i}"));
    }
    Ok(cmp.row(
        "rmsprop_sparse",
        n,
        "2/3 of vertices touched; fresh state, zero and 1e-8..1e4 gradients; flags cleared".into(),
    ))
}

pub fn check_tv(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    let (g, _, _) = test_scene(seed, 40, 0);
    let mut cmp = Compare::new(1e-6, 1e-4);
    let links = gpu.upload(&g.links)?;
    let slots = g.slots() as u32;
    let mut cases = 0;
    for (data, channels) in [(&g.density, 1u32), (&g.sh, SH_DIM as u32)] {
        // A chunk in the middle, one running off the end of the slot range, and the whole
        // grid, each with other touched bits.
        for (start, count, touch) in [
            (slots / 3, slots / 10, TOUCH_ALL),
            (slots - slots / 20, slots / 10, 2),
            (0, slots, 0),
        ] {
            let c = TvChunk {
                res: g.res,
                start,
                count,
                channels,
                scale: 0.7,
                touch,
            };
            let mut want = vec![0.0f32; data.len()];
            let mut want_touched = vec![0u32; g.allocated()];
            tv(&g.links, data, &mut want, &mut want_touched, &c);
            let db = gpu.upload(data)?;
            let gb = gpu.zeros::<f32>(data.len())?;
            let step = gpu.upload(&step_buffer(g.allocated(), &[]))?;
            let mut b = gpu.batch()?;
            record_tv(&mut b, &links, &db, &gb, &step, &c)?;
            b.submit()?;
            let got: Vec<f32> = gb.download()?;
            for (i, (&a, &b)) in got.iter().zip(&want).enumerate() {
                cmp.value(a as f64, b as f64, || {
                    format!("{channels}-channel element {i} (chunk at {start})")
                });
            }
            let flags: Vec<u32> = step.download_range(STEP_FLAGS, g.allocated())?;
            for (i, (&a, &b)) in flags.iter().zip(&want_touched).enumerate() {
                cmp.value(a as f64, b as f64, || {
                    format!("touched flag {i} (bits {touch})")
                });
            }
            cases += count as usize;
        }
    }
    Ok(cmp.row(
        "tv",
        cases,
        "σ and SH, chunk inside, past the end and the whole grid; touched bits 1, 2, 0: flags \
         exact"
            .into(),
    ))
}

/// `background_step` against `cpu::background_step::background_step` on 64 random states, one dispatch each:
/// fresh (r = 0) and running averages, zero gradients, 1e-6..1e2 magnitudes, steps that leave
/// [0, 1] (the clamp). Same tolerance as rmsprop_sparse (the same update).
pub fn check_background_step(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    let mut rng = Pcg64::seed_from_u64(seed);
    let (lr, beta, eps) = (0.05, 0.95, 1e-8);
    let cases: Vec<Background> = (0..64)
        .map(|i| {
            let mut bg = Background::new(std::array::from_fn(|_| rng.random_range(0.0..1.0)), true);
            for ch in 0..3 {
                let mag = 10f32.powi((i + ch) as i32 % 9 - 6);
                bg.grad[ch] = if (i + ch) % 7 == 0 {
                    0.0
                } else {
                    rng.random_range(-1.0..1.0) * mag
                };
                bg.avg[ch] = if i % 4 == 0 {
                    0.0
                } else {
                    rng.random_range(0.0..2.0) * mag * mag
                };
            }
            // Colours at the edges, stepped outwards: the clamp decides.
            if i % 8 == 1 {
                bg.rgb = [0.01, 0.99, 0.0];
                bg.grad = [1.0, -1.0, 0.5];
            }
            bg
        })
        .collect();
    let buf = gpu.upload(&cases)?;
    let size = std::mem::size_of::<Background>() as u64;
    let mut b = gpu.batch()?;
    for i in 0..cases.len() as u64 {
        b.dispatch_1d(
            &kernels::background_step::INFO,
            &kernels::background_step::Push {
                bg: buf.address() + i * size,
                lr,
                beta,
                eps,
                ..Default::default()
            },
            3,
        )?;
    }
    b.submit()?;
    let got: Vec<Background> = buf.download()?;
    let mut cmp = Compare::new(1e-6, 1e-5);
    let mut clamped = 0;
    for (i, (g, mut w)) in got.iter().zip(cases).enumerate() {
        let before = w.rgb;
        background_step(&mut w, lr, beta, eps);
        clamped += (0..3)
            .filter(|&ch| (w.rgb[ch] == 0.0 || w.rgb[ch] == 1.0) && w.rgb[ch] != before[ch])
            .count();
        for (name, a, b) in [
            ("rgb", g.rgb, w.rgb),
            ("grad", g.grad, w.grad),
            ("avg", g.avg, w.avg),
        ] {
            for ch in 0..3 {
                cmp.value(a[ch] as f64, b[ch] as f64, || {
                    format!("case {i} {name}[{ch}]")
                });
            }
        }
    }
    Ok(cmp.row(
        "background_step",
        got.len(),
        format!("{clamped} channels clamped to 0 or 1"),
    ))
}
