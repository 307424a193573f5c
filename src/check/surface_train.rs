//! Parity of `glsl/surface_train.comp` (the stage-2 fused training pass) with
//! `cpu::surface_train::train`, through `VulkanSurface::gradients`, on the random test scenes of
//! `surface_fwd` (SDF-like δ with 5 levels, 3 % unallocated vertices, random σα and SH, random and
//! adversarial rays) plus a quantised variant whose δ sits on a lattice of the level spacing
//! (levels through vertices, flat cell faces), and a scene built to trip the f′ guard
//! (`guard_scene`). Random targets; λH
//! and λc large enough that their gradients matter. Passes: a = 3.5 / stop 1e-4 (fractional γ,
//! truncation) and a = 8 / stop 1e-3.
//!
//! Each pass runs three rounds. First on every ray: a ray whose hit count differs between the
//! backends is excused (near-tangent or face-ambiguous crossings, as in `surface_fwd`; capped at
//! 0.5 % of the rays). Then on the rays that agree:
//! - per-ray squared error, entropy and consistency: |Δ| ≤ 1e-4 + 1e-3·|cpu| (the f32 roots, `exp`,
//!   `log` and `cos` differ by ulps between lavapipe and the twin);
//! - counters: hits exact; the others within 0.1 % + 2 (a ray through a vertex or along an edge
//!   may visit one cell more or less, since lavapipe does not fuse `ray_unit`'s fma while the twin
//!   does; a degenerate crossing behind the last hit can decide the cut; the guard compares f′
//!   against a threshold and the scatter skips exact zeros, and an ulp can flip either);
//! - touched flags: equal;
//! - gradients per parameter type (δ, σα, SH): relative L2 ≤ 1e-3, and elementwise
//!   |Δ| ≤ 1e-4·max|g| + 1e-3·|g| for all but 0.1 % of the elements (atomic summation order);
//!   the background's (rays composited on [`TEST_BACKGROUND`], learned): relative L2 ≤ 1e-3
//!   (a sum over rays of dL/dC·T, each as close as the per-ray losses).
//!
//! Last on the well-conditioned rays, those whose every hit has |f′| ≥ [`ILL_CONDITIONED`]·(the
//! cell's δ range) and |σα| ≥ [`ILL_CONDITIONED`]·(the cell's σα range): the same gradient test
//! with relative L2 ≤ 1e-4. (Where f′ is small an ulp of the f32 root moves the hit far, and the δ
//! gradient goes as 1/f′; where σα at the hit is a near-cancelling trilerp, an ulp of the hit
//! position changes α by far more than an ulp, which a contracting compiler, or the twin's `fused`
//! mode, produces: such rays, and all of the guard scene's, keep the looser bound.) In the guard scene every hit must be
//! guarded and no δ gradient may appear on either backend.

use super::surface_fwd::{test_rays, test_scene, SurfaceScene, RES};
use super::{background_msi, grad_outliers, rel_l2, CheckRow, Compare, TEST_BACKGROUND};
use crate::abi::buffers::Background;
use crate::cpu::surface_blocks::build_blocks;
use crate::cpu::surface_train::{
    hit_point, trace_ray, train, RayLoss, SurfaceGrads, TrainCounts, TrainInput,
};
use crate::gpu::Gpu;
use crate::grid::surface::SurfaceGrid;
use crate::grid::SH_DIM;
use crate::math::background_msi::SphereTable;
use crate::math::surface::SurfaceParams;
use crate::math::surface::{Truncation, TruncationCount};
use crate::math::surface_blocks::{SkipRef, SURF_BLOCK_SHIFT_VULKAN};
use crate::math::trilerp::trilerp_grad;
use crate::stage::StageBackend;
use crate::surface::{
    batch_loss, surface_params, SurfaceGradients, SurfaceStepParams, VulkanSurface,
};
use anyhow::Result;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use std::sync::Arc;

/// Largest fraction of rays whose hit counts may differ (excused as near-degenerate).
pub const EXCUSED_CAP_FRAC: f64 = 0.005;

/// The stage-2 grid of a test scene (its scale and offset come back from `surface_params`).
pub fn scene_grid(s: &SurfaceScene) -> SurfaceGrid {
    SurfaceGrid {
        res: [s.n; 3],
        center: [0.0; 3],
        radius: [s.n as f32 / 32.0; 3],
        links: s.links.clone(),
        delta: s.delta.clone(),
        opacity: s.opacity.clone(),
        sh: s.sh.clone(),
        levels: s.levels.clone(),
        gradient_scale: 1.0,
    }
}

/// Step parameters of a pass: truncation (a plain a: counted per ray), stop threshold and the
/// loss weights (no regulariser).
pub fn pass_params(
    truncation: impl Into<Truncation>,
    stop_thresh: f32,
    lambda_h: f32,
    lambda_c: f32,
) -> SurfaceStepParams {
    SurfaceStepParams {
        lr_delta: 0.0,
        lr_opacity: 0.0,
        lr_sh: 0.0,
        beta: 0.95,
        eps: 1e-8,
        truncation: truncation.into(),
        stop_thresh,
        lambda_h,
        lambda_c,
        regs: Default::default(),
        lr_bg: 0.0,
    }
}

/// The CPU twin's outputs: per-ray losses, counters, gradients (δ, σα, SH, background) and
/// touched flags.
pub struct CpuTrain {
    pub ray_loss: Vec<RayLoss>,
    pub counts: TrainCounts,
    pub grads: [Vec<f32>; 3],
    pub background: [f32; 3],
    pub touched: Vec<u32>,
}

/// The background of the training parity passes: [`TEST_BACKGROUND`], learned (its gradient is
/// compared too).
pub fn test_background() -> Background {
    Background::new(TEST_BACKGROUND, true)
}

/// Run the CPU twin on `grid` the way the backends do (surface_params, batch_loss), on
/// [`test_background`].
pub fn cpu_train(
    grid: &SurfaceGrid,
    batch: TrainInput,
    p: &SurfaceStepParams,
    spheres: Option<&Arc<SphereTable>>,
) -> Result<CpuTrain> {
    let TrainInput {
        rays,
        targets,
        weights,
    } = batch;
    let rows = grid.delta.len();
    let mut grads = [vec![0.0; rows], vec![0.0; rows], vec![0.0; rows * SH_DIM]];
    let mut touched = vec![0u32; rows];
    let [gd, go, gs] = &mut grads;
    let mut background = [0.0; 3];
    // The skip structure the Vulkan backend walks with (its block edge).
    let blocks = build_blocks(&grid.as_ref(), &grid.levels, 0.0, SURF_BLOCK_SHIFT_VULKAN)?;
    let (ray_loss, counts) = train(
        &grid.as_ref(),
        TrainInput {
            rays,
            targets,
            weights,
        },
        &surface_params(grid, p.truncation, p.stop_thresh, TEST_BACKGROUND)
            .with_spheres(spheres.cloned()),
        &batch_loss(rays.len() / 6, p),
        Some(SkipRef {
            words: &blocks,
            shift: SURF_BLOCK_SHIFT_VULKAN,
        }),
        SurfaceGrads {
            delta: gd,
            opacity: go,
            sh: gs,
            touched: &mut touched,
            background: Some(&mut background),
        },
    )?;
    Ok(CpuTrain {
        ray_loss,
        counts,
        grads,
        background,
        touched,
    })
}

/// δ snapped to a lattice of a quarter of the scene's smallest level spacing: levels pass through
/// vertices and many cells have flat faces.
fn quantised(mut s: SurfaceScene) -> SurfaceScene {
    let step = s
        .levels
        .windows(2)
        .map(|w| w[1] - w[0])
        .fold(f32::INFINITY, f32::min)
        / 4.0;
    let base = s.levels[0];
    for d in &mut s.delta {
        *d = base + ((*d - base) / step).round() * step;
    }
    s
}

/// How well a ray's figures are determined by its inputs: the smallest, over its composited hits,
/// of |f′(s)|/(max − min of the cell's δ) and |σα(p)|/(max − min of the cell's σα) (∞ without hits).
/// The first bounds how far an ulp of δ moves the root (the δ gradient goes as 1/f′); the second
/// how much an ulp of the hit position changes α relative to itself (a σα that is a near-cancelling
/// trilerp of larger corners: an f32 position error of ~ulp(t) ≈ 4e-6 voxels then moves α by
/// |∇σα|·4e-6/σα ≤ √3·range·4e-6/(0.1·range) ≈ 7e-5 relative at the threshold).
fn conditioning(grid: &SurfaceGrid, ro: [f32; 3], rd: [f32; 3], sp: &SurfaceParams) -> f32 {
    let tr = trace_ray(
        &grid.as_ref(),
        ro,
        rd,
        sp,
        None,
        &mut TrainCounts::default(),
    );
    let range = |v: &[f32; 8]| {
        let lo = v.iter().copied().fold(f32::INFINITY, f32::min);
        let hi = v.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        hi - lo
    };
    tr.hits[..tr.n]
        .iter()
        .map(|h| {
            let p = hit_point(h, tr.dn);
            let (_, g) = trilerp_grad(&h.c, p);
            let f1 = g[0] * tr.dn[0] + g[1] * tr.dn[1] + g[2] * tr.dn[2];
            let sa: [f32; 8] = h.lk.map(|l| grid.opacity[l as usize]);
            let (sa_p, _) = trilerp_grad(&sa, p);
            (f1.abs() / range(&h.c)).min(sa_p.abs() / range(&sa))
        })
        .fold(f32::INFINITY, f32::min)
}

/// Hits below this fraction (see [`conditioning`]) make a ray ill-conditioned: an ulp of δ moves
/// the root by ≳ 1e-6 voxels and the δ gradient by more, or an ulp of the hit position moves α
/// by ≳ 1e-4 relative.
pub const ILL_CONDITIONED: f32 = 0.1;

/// Figures of one pass, for the note.
struct PassNote {
    excused: usize,
    ill: usize,
    kept: usize,
    /// Relative L2 of dδ, dσα, dSH: well-conditioned rays, then all agreeing rays.
    rel: [f64; 3],
    rel_all: [f64; 3],
    counts: TrainCounts,
}

/// A batch for a pass: rays, targets and optional per-ray importance weights.
struct RaySet {
    rays: Vec<f32>,
    targets: Vec<f32>,
    weights: Option<Vec<f32>>,
}

impl RaySet {
    /// The rays (targets, weights) with the given indices.
    fn subset(&self, idx: &[usize]) -> RaySet {
        RaySet {
            rays: idx
                .iter()
                .flat_map(|&i| self.rays[6 * i..6 * i + 6].to_vec())
                .collect(),
            targets: idx
                .iter()
                .flat_map(|&i| self.targets[3 * i..3 * i + 3].to_vec())
                .collect(),
            weights: self
                .weights
                .as_ref()
                .map(|w| idx.iter().map(|&i| w[i]).collect()),
        }
    }
}

/// Gradients of both backends on `rays`: relative L2 per parameter type; a failure message when
/// one exceeds `limit` or more than 0.1 % of its elements miss |Δ| ≤ 1e-4·max|g| + 1e-3·|g|.
fn compare_grads(
    got: &SurfaceGradients,
    want: &CpuTrain,
    limit: f64,
    what: &str,
    errs: &mut Vec<String>,
) -> [f64; 3] {
    let mut rel = [0.0; 3];
    for (t, (name, a, b)) in [
        ("dδ", &got.delta, &want.grads[0]),
        ("dσα", &got.opacity, &want.grads[1]),
        ("dSH", &got.sh, &want.grads[2]),
    ]
    .into_iter()
    .enumerate()
    {
        let e = rel_l2(a, b);
        rel[t] = e;
        let bad = grad_outliers(a, b);
        if e > limit || bad > b.len() / 1000 {
            errs.push(format!(
                "{what} {name}: rel L2 {e:.2e} (limit {limit:.0e}), {bad} elements off"
            ));
        }
    }
    let e = rel_l2(&got.background, &want.background);
    if e > limit {
        errs.push(format!(
            "{what} dbg: rel L2 {e:.2e} (limit {limit:.0e}): gpu {:?} cpu {:?}",
            got.background, want.background
        ));
    }
    rel
}

/// One pass: its parameters, its name, and whether every hit must be guarded (the guard scene).
struct Pass<'a> {
    p: &'a SurfaceStepParams,
    what: &'a str,
    all_guarded: bool,
    /// Spheres behind the surfaces (kept: stage 2 does not train them).
    spheres: Option<&'a Arc<SphereTable>>,
}

fn run_pass(
    gpu: &Gpu,
    grid: &SurfaceGrid,
    all: &RaySet,
    pass: &Pass,
    cmp: &mut Compare,
) -> Result<PassNote> {
    let (p, what, all_guarded) = (pass.p, pass.what, pass.all_guarded);
    let train_gpu = |b: &RaySet| {
        let mut vk = VulkanSurface::new(gpu, grid.clone())?;
        vk.set_background(test_background())?;
        vk.set_spheres(pass.spheres.map(|s| (**s).clone()))?;
        vk.gradients(&b.rays, &b.targets, b.weights.as_deref(), p)
    };
    let train_cpu = |b: &RaySet| {
        let batch = TrainInput {
            rays: &b.rays,
            targets: &b.targets,
            weights: b.weights.as_deref(),
        };
        cpu_train(grid, batch, p, pass.spheres)
    };
    // 1: every ray; keep those whose hit counts agree.
    let want = train_cpu(all)?;
    let got = train_gpu(all)?;
    let n_rays = all.rays.len() / 6;
    let keep: Vec<usize> = (0..n_rays)
        .filter(|&i| got.ray_loss[i].hits == want.ray_loss[i].hits)
        .collect();
    let excused = n_rays - keep.len();
    // 2: the agreeing rays: losses, counters, touched flags, gradients within 1e-3.
    let kept = all.subset(&keep);
    let rays_k = &kept.rays;
    let want = train_cpu(&kept)?;
    let got = train_gpu(&kept)?;
    let mut errs = Vec::new();
    for (i, (g, w)) in got.ray_loss.iter().zip(&want.ray_loss).enumerate() {
        if g.hits != w.hits {
            errs.push(format!("{what} ray {i}: hits {} vs {}", g.hits, w.hits));
        }
        cmp.value(g.sq_err as f64, w.sq_err as f64, || {
            format!("{what} ray {i} squared error")
        });
        cmp.value(g.entropy as f64, w.entropy as f64, || {
            format!("{what} ray {i} entropy")
        });
        cmp.value(g.consistency as f64, w.consistency as f64, || {
            format!("{what} ray {i} consistency")
        });
    }
    let (gc, wc) = (got.counts, want.counts);
    // Hits exactly; these within 0.1 % + 2.
    let near = |g: u32, w: u32| (g as f64 - w as f64).abs() <= 1e-3 * w as f64 + 2.0;
    let close = [
        (gc.cells, wc.cells),
        (gc.solves, wc.solves),
        (gc.culled, wc.culled),
        (gc.cut, wc.cut),
        (gc.guarded, wc.guarded),
        (gc.atomic_adds, wc.atomic_adds),
    ];
    if !(gc.hits == wc.hits && close.into_iter().all(|(g, w)| near(g, w))) {
        errs.push(format!("{what}: counters gpu {gc:?} cpu {wc:?}"));
    }
    let touched_off = got
        .touched
        .iter()
        .zip(&want.touched)
        .filter(|(g, w)| (**g != 0) != (**w != 0))
        .count();
    if touched_off > 0 {
        errs.push(format!("{what}: {touched_off} touched flags differ"));
    }
    let rel_all = compare_grads(&got, &want, 1e-3, &format!("{what} (all)"), &mut errs);
    if all_guarded
        && (wc.guarded != wc.hits
            || gc.guarded != gc.hits
            || got.delta.iter().chain(&want.grads[0]).any(|&g| g != 0.0))
    {
        errs.push(format!(
            "{what}: every hit should be guarded and give δ no gradient"
        ));
    }
    // 3: the well-conditioned rays: gradients within 1e-4.
    let sp = surface_params(grid, p.truncation, p.stop_thresh, TEST_BACKGROUND)
        .with_spheres(pass.spheres.cloned());
    let good: Vec<usize> = (0..keep.len())
        .filter(|&i| {
            let r = &rays_k[6 * i..6 * i + 6];
            conditioning(grid, [r[0], r[1], r[2]], [r[3], r[4], r[5]], &sp) >= ILL_CONDITIONED
        })
        .collect();
    let rel = if good.is_empty() {
        [0.0; 3]
    } else {
        let good = kept.subset(&good);
        let want = train_cpu(&good)?;
        let got = train_gpu(&good)?;
        compare_grads(&got, &want, 1e-4, what, &mut errs)
    };
    for msg in errs {
        cmp.failures += 1;
        cmp.first_failure.get_or_insert(msg);
    }
    Ok(PassNote {
        excused,
        ill: keep.len() - good.len(),
        kept: keep.len(),
        rel,
        rel_all,
        counts: wc,
    })
}

/// A field built to trip the f′ guard: δ = (x − c)(y − c)(z − c) + ε·((x − c) + (y − c) + (z − c))
/// in grid units (multilinear, so every cell reproduces it exactly), c the centre of the middle
/// cell, ε = 1.25e-4, one level at 0; rays along (1, 1, 1) through points within 1e-3 of (c, c, c),
/// their directions perturbed by 1e-3. Along such a ray δ is monotone (a single, well-bracketed
/// front-face root near the centre) but f′ ≈ √3·ε ≈ 2.2e-4, below 1e-3 of the cell’s δ range (≈ 2.5e-4), while the root stays
/// well enough conditioned (an f error of 1e-8 moves it by ~5e-5 voxels) for the loss comparison.
fn guard_scene(seed: u64, n_rays: usize) -> (SurfaceGrid, Vec<f32>) {
    let n = 8u32;
    let c = 3.5f32;
    let mut rng = Pcg64::seed_from_u64(seed ^ 0x6a4d);
    let mut g = SurfaceGrid {
        res: [n; 3],
        center: [0.0; 3],
        radius: [n as f32 / 32.0; 3],
        links: Vec::new(),
        delta: Vec::new(),
        opacity: Vec::new(),
        sh: Vec::new(),
        levels: vec![0.0],
        gradient_scale: 1.0,
    };
    for slot in 0..(n * n * n) as usize {
        let v = [slot / 64, slot / 8 % 8, slot % 8].map(|x| x as f32 - c);
        g.links.push(slot as i32);
        g.delta
            .push(v[0] * v[1] * v[2] + 1.25e-4 * (v[0] + v[1] + v[2]));
        g.opacity.push(rng.random_range(0.2..3.0));
        g.sh.extend((0..27).map(|_| rng.random_range(-0.4f32..0.4)));
    }
    // grid = p·16 + 3.5 (surface_params of this grid).
    let mut rays = Vec::with_capacity(6 * n_rays);
    for _ in 0..n_rays {
        let at: [f32; 3] = std::array::from_fn(|_| c + rng.random_range(-1e-3..1e-3));
        let d: [f32; 3] = std::array::from_fn(|_| 1.0 + rng.random_range(-1e-3..1e-3));
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let d = d.map(|x| x / len);
        let o: [f32; 3] = std::array::from_fn(|i| at[i] - 6.0 * d[i]);
        rays.extend(o.map(|x| (x - c) / 16.0));
        rays.extend(d);
    }
    (g, rays)
}

/// The parity row.
pub fn check(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    check_with(gpu, seed, None)
}

/// The row on the random scene with spheres behind the surfaces (`background_msi::
/// test_spheres`, kept), a = 3.5: the per-ray tolerance adds their bound on B times the loss's
/// slope in B (Σ_ch 2·|C − target| ≤ 3·2·1.4 < 9, times the largest ω, 3.25).
pub fn check_spheres(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    check_with(
        gpu,
        seed,
        Some(Arc::new(background_msi::test_spheres(seed))),
    )
}

fn check_with(gpu: &Gpu, seed: u64, spheres: Option<Arc<SphereTable>>) -> Result<CheckRow> {
    let bound = spheres.as_deref().map_or(0.0, background_msi::abs_bound);
    let mut cmp = Compare::new(1e-4 + 9.0 * 3.25 * bound, 1e-3);
    let mut notes = Vec::new();
    let (mut excused, mut cases, mut worst) = (0usize, 0usize, [0.0f64; 3]);
    let mut total_rays = 0usize;
    let mut variants = Vec::new();
    for (name, scene) in [
        ("random", test_scene(seed, RES)),
        ("quantised", quantised(test_scene(seed ^ 0x9e37, RES))),
    ] {
        let rays = test_rays(&scene, seed, 3000);
        variants.push((name, scene_grid(&scene), rays));
    }
    if spheres.is_none() {
        let (g, rays) = guard_scene(seed, 200);
        variants.push(("guard", g, rays));
    } else {
        variants.truncate(1);
    }
    let (mut ill, mut worst_all) = (0usize, [0.0f64; 3]);
    for (variant, grid, rays) in &variants {
        let mut rng = Pcg64::seed_from_u64(seed ^ 0x7a26_e7a5);
        let targets: Vec<f32> = (0..rays.len() / 6 * 3).map(|_| rng.random()).collect();
        // The random scene's rays carry importance weights (a focused batch's): every per-ray
        // term and output is ω times the unweighted one on both sides.
        let weights = (*variant == "random").then(|| {
            (0..rays.len() / 6)
                .map(|i| 0.25 + 0.5 * (i % 7) as f32)
                .collect()
        });
        let batch = RaySet {
            rays: rays.clone(),
            targets,
            weights,
        };
        let counted = |a, count| Truncation { a, count };
        let settings = [
            (3.5f32.into(), 1e-4f32),
            (8.0.into(), 1e-3),
            (counted(1.5, TruncationCount::Structure), 1e-4),
            (counted(2.5, TruncationCount::Through), 1e-4),
        ];
        let settings = if spheres.is_some() {
            &settings[..1]
        } else {
            &settings[..]
        };
        for &(t, stop) in settings {
            let p = pass_params(t, stop, 0.5, 0.2);
            let what = format!(
                "{variant}{} a {} counted per {:?}",
                if batch.weights.is_some() {
                    " weighted"
                } else {
                    ""
                },
                t.a,
                t.count
            );
            let guard = *variant == "guard";
            let pass = Pass {
                p: &p,
                what: &what,
                all_guarded: guard,
                spheres: spheres.as_ref(),
            };
            let n = run_pass(gpu, grid, &batch, &pass, &mut cmp)?;
            excused += n.excused;
            ill += n.ill;
            cases += n.kept;
            total_rays += rays.len() / 6;
            for t in 0..3 {
                worst[t] = worst[t].max(n.rel[t]);
                worst_all[t] = worst_all[t].max(n.rel_all[t]);
            }
            notes.push(format!("{what}: {:?}", n.counts));
        }
    }
    let cap = (EXCUSED_CAP_FRAC * total_rays as f64).floor() as usize;
    if excused > cap {
        cmp.failures += 1;
        cmp.first_failure
            .get_or_insert_with(|| format!("{excused} rays with differing hit counts > cap {cap}"));
    }
    Ok(cmp.row(
        if spheres.is_some() {
            "surface_train_spheres"
        } else {
            "surface_train"
        },
        cases,
        format!(
            "grad rel L2 δ/σα/SH {:.1e}/{:.1e}/{:.1e} on well-conditioned rays (≤ 1e-4), \
             {:.1e}/{:.1e}/{:.1e} with the {ill} ill-conditioned ones (|f′| or |σα| < {ILL_CONDITIONED}·range; \
             ≤ 1e-3); elementwise |Δ| ≤ 1e-4·max|g| + 1e-3·|g| for all but 0.1 %; touched \
             equal; guard scene: δ gradients 0, every hit guarded; {excused} rays excused (cap \
             {cap}); {}",
            worst[0],
            worst[1],
            worst[2],
            worst_all[0],
            worst_all[1],
            worst_all[2],
            notes.join("; ")
        ),
    ))
}
