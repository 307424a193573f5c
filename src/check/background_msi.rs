//! Parity of `glsl/background_msi_eval.comp` (the library `glsl/lib/background_msi.glsl`) with
//! `cpu::background_msi_eval`: each ray's background colour and T_L, and the table's gradient.
//!
//! Rays come from cameras on a sphere of radius 4 around spheres of radius 1.2 … 30 (some
//! spheres the cameras are outside of, some rays missing them), among them rays along the axes
//! and the octahedral map's folds (z = 0, x = 0, y = 0). The table is random (σ ∈ [−0.5, 3]:
//! transparent, clamped and nearly opaque texels; colours ∈ [−0.2, 1.2]: clamped ones).
//! Rays that pass a sphere nearer than 0.1 r to tangency are left out: there the exit point's
//! square root amplifies rounding without bound (a geometric fact, not a kernel's).

use super::{grad_outliers, rel_l2, CheckRow, Compare, TEST_BACKGROUND};
use crate::abi::buffers::{Background, BackgroundSpheres};
use crate::abi::train::BackgroundStep;
use crate::gpu::{Gpu, SphereBuffers};
use crate::kernels;
use crate::kernels::background_msi_eval::{Push, INFO};
use crate::math::background_msi::SphereTable;
use crate::math::background_msi::TEXEL;
use anyhow::Result;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// Texels per side of the test maps.
const SIZE: u32 = 16;
/// Spheres of the test.
const LAYERS: u32 = 8;

/// `shape` with random texel values: σ ∈ [−0.5, 3] (transparent, clamped and nearly opaque
/// texels), colours ∈ [−0.2, 1.2] (clamped ones); running averages zero.
fn random_spheres(shape: BackgroundSpheres, rng: &mut Pcg64) -> SphereTable {
    let table: Vec<f32> = (0..shape.table_len())
        .map(|i| match i % TEXEL {
            0 => rng.random_range(-0.5f32..3.0),
            _ => rng.random_range(-0.2f32..1.2),
        })
        .collect();
    SphereTable {
        avg: vec![0.0; table.len()],
        shape,
        table,
    }
}

/// The test's spheres, rays (6 floats) and upstream gradients (3 floats).
pub fn cases(count: usize, seed: u64) -> (SphereTable, Vec<f32>, Vec<f32>) {
    let mut rng = Pcg64::seed_from_u64(seed);
    let shape = BackgroundSpheres::spanning([0.05, -0.1, 0.2], 1.2, 30.0, LAYERS, SIZE);
    let spheres = random_spheres(shape, &mut rng);
    let s = &spheres.shape;
    let (mut rays, mut upstream) = (Vec::new(), Vec::new());
    while rays.len() < 6 * count {
        let o: [f32; 3] = loop {
            let v = [(); 3].map(|_| rng.random_range(-1f32..1.0));
            let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            if n > 0.1 {
                break v.map(|x| 4.0 * x / n);
            }
        };
        let d = match rays.len() / 6 % 4 {
            // Along an axis or in a fold's plane.
            0 => {
                let mut d = [(); 3].map(|_| rng.random_range(-1f32..1.0));
                d[rng.random_range(0..3)] = 0.0;
                if rng.random_bool(0.3) {
                    d[rng.random_range(0..3)] = 0.0;
                }
                d
            }
            _ => [(); 3].map(|_| rng.random_range(-1f32..1.0)),
        };
        let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if n < 1e-3 {
            continue;
        }
        let d = d.map(|x| x / n);
        if near_tangent(s, o, d) {
            continue;
        }
        rays.extend_from_slice(&o);
        rays.extend_from_slice(&d);
        upstream.extend((0..3).map(|_| rng.random_range(-1f32..1.0)));
    }
    (spheres, rays, upstream)
}

/// Whether the ray passes some sphere within 0.1 r of tangency (f64).
fn near_tangent(s: &BackgroundSpheres, o: [f32; 3], d: [f32; 3]) -> bool {
    let oc: [f64; 3] = std::array::from_fn(|i| (o[i] - s.centre[i]) as f64);
    let b: f64 = (0..3).map(|i| oc[i] * d[i] as f64).sum();
    let h2: f64 = (0..3).map(|i| (oc[i] - b * d[i] as f64).powi(2)).sum();
    (0..s.layers).any(|l| {
        let r = s.radius(l) as f64;
        let disc = r * r - h2;
        disc.abs() < 0.01 * r * r
    })
}

/// Runs the kernel: per ray (B, T_L), and the table's gradient.
pub fn run_gpu(
    gpu: &Gpu,
    spheres: &SphereTable,
    rays: &[f32],
    upstream: &[f32],
) -> Result<(Vec<f32>, Vec<f32>)> {
    let n = rays.len() / 6;
    let sp = SphereBuffers::upload(gpu, spheres)?;
    let r = gpu.upload(rays)?;
    let u = gpu.upload(upstream)?;
    let out = gpu.zeros::<f32>(4 * n)?;
    let push = Push {
        spheres: sp.shape_buf.address(),
        rays: r.address(),
        upstream: u.address(),
        out_: out.address(),
        rgb: TEST_BACKGROUND,
        n: n as u32,
    };
    gpu.run_1d(&INFO, &push, n as u32)?;
    Ok((out.download()?, sp.take_grad()?))
}

/// Spheres for the render and training rows of both stages: around their test grids' box
/// [−1, 1]³ (cameras within 3 of it), 4 spheres of 8² texels, random values as [`cases`].
pub fn test_spheres(seed: u64) -> SphereTable {
    let mut rng = Pcg64::seed_from_u64(seed ^ 0x5be7e5);
    random_spheres(
        BackgroundSpheres::spanning([0.0; 3], 3f32.sqrt(), 12.0, 4, 8),
        &mut rng,
    )
}

/// Elementwise bound on B and T_L for `s`'s spheres: the octahedral coordinate carries ≲ 2⁻¹⁸
/// of error (its division and |p|₁ sum, the exit point's square root away from tangency: tens of
/// ulps), so the texel position ≲ size·2⁻¹⁹ texels, and a value read at most that times the
/// largest step between neighbouring texel values (at most the table's range) per sphere.
pub fn abs_bound(s: &SphereTable) -> f64 {
    let (lo, hi) = s
        .table
        .iter()
        .fold((f32::MAX, f32::MIN), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    s.shape.layers as f64 * s.shape.size as f64 * 2f64.powi(-19) * (hi - lo) as f64
}

/// 50k rays, GPU against the CPU twin.
pub fn check(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    let (spheres, rays, upstream) = cases(50_000, seed);
    let (got, got_grad) = run_gpu(gpu, &spheres, &rays, &upstream)?;
    let mut want = vec![0.0; got.len()];
    let mut want_grad = vec![0.0; spheres.table.len()];
    crate::cpu::background_msi_eval(
        &spheres.shape,
        &spheres.table,
        &rays,
        &upstream,
        TEST_BACKGROUND,
        &mut want,
        &mut want_grad,
    );
    // The bound, plus 16 ulp of 1 for exp() and the products.
    let mut cmp = Compare::new(abs_bound(&spheres) + 16.0 * f64::from(f32::EPSILON), 0.0);
    for (i, (g, w)) in got.chunks_exact(4).zip(want.chunks_exact(4)).enumerate() {
        for k in 0..4 {
            cmp.value(g[k] as f64, w[k] as f64, || {
                format!("ray {i} {}", ["B.r", "B.g", "B.b", "T"][k])
            });
        }
    }
    // The gradient sums many rays per texel in another order: the training kernels' bounds.
    let e = rel_l2(&got_grad, &want_grad);
    let bad = grad_outliers(&got_grad, &want_grad);
    let nonzero = want_grad.iter().filter(|&&x| x != 0.0).count();
    if e > 1e-4 || bad > want_grad.len() / 1000 || nonzero < want_grad.len() / 2 {
        cmp.failures += 1;
        cmp.first_failure.get_or_insert_with(|| {
            format!("table gradient: rel L2 {e:.2e}, {bad} off, {nonzero} nonzero")
        });
    }
    let note = format!(
        "B, T_L: |Δ| ≤ layers·size·2⁻¹⁹·(table range) + 16 ulp (texel position error × largest texel step); \
         table grad rel L2 {e:.1e} (≤ 1e-4; ≤ 0.1% elements off), {nonzero} of {} nonzero",
        want_grad.len()
    );
    Ok(cmp.row(INFO.name, rays.len() / 6, note))
}

/// `background_spheres_step` against its twin: a random table whose gradient spans 1e-6 … 1e2
/// (a sixth of it zero: those values must not move) and whose running averages are zero (a
/// first step) for a quarter of the values; the tolerance of `background_step`'s row (the same
/// RMSProp arithmetic). Without the spheres' TV (its own row, [`check_tv`]).
pub fn check_step(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    let mut rng = Pcg64::seed_from_u64(seed);
    let (
        SphereTable {
            shape: s, table, ..
        },
        _,
        _,
    ) = cases(0, seed);
    let grad: Vec<f32> = (0..table.len())
        .map(|i| {
            if i % 6 == 5 {
                0.0
            } else {
                rng.random_range(-1f32..1.0) * 10f32.powi(i as i32 % 9 - 6)
            }
        })
        .collect();
    let avg: Vec<f32> = (0..table.len())
        .map(|i| {
            if i % 4 == 0 {
                0.0
            } else {
                rng.random_range(0f32..2.0) * (grad[i] * grad[i]).max(1e-12)
            }
        })
        .collect();
    let mut want = SphereTable {
        shape: BackgroundSpheres { learn: 1, ..s },
        table,
        avg,
    };
    let bufs = SphereBuffers::upload(gpu, &want)?;
    bufs.grad.write(&grad)?;
    // The spheres' TV has its own row (`check_tv`).
    let step = BackgroundStep {
        lr: 0.01,
        lr_sigma: 30.0,
        sphere_tv: 0.0,
        beta: 0.95,
        eps: 1e-8,
    };
    let [lr_sigma, lr_colour] = step.sphere_rates();
    // Buffers the batch names live until it is submitted (not temporaries of the call).
    let (bg, step_record) = (gpu.upload(&[Background::default()])?, gpu.zeros::<u32>(1)?);
    let mut b = gpu.batch()?;
    crate::gpu::record_background_step(&mut b, &bg, Some(&bufs), &step_record, &step)?;
    b.submit()?;
    let got = bufs.download()?;
    let got_grad = bufs.take_grad()?;
    let mut want_grad = grad.clone();
    crate::cpu::background_spheres_step::background_spheres_step(
        &mut want,
        &mut want_grad,
        lr_sigma,
        lr_colour,
        step.beta,
        step.eps,
    );
    let mut cmp = Compare::new(1e-6, 1e-5);
    for (name, a, b) in [
        ("value", &got.table, &want.table),
        ("avg", &got.avg, &want.avg),
        ("grad", &got_grad, &want_grad),
    ] {
        for (i, (x, y)) in a.iter().zip(b.iter()).enumerate() {
            cmp.value(*x as f64, *y as f64, || format!("{name} {i}"));
        }
    }
    let still = grad.iter().filter(|&&g| g == 0.0).count();
    Ok(cmp.row(
        kernels::background_spheres_step::INFO.name,
        grad.len(),
        format!("{still} values without gradient (left as they were); σ rate {lr_sigma}, colour rate {lr_colour}"),
    ))
}

/// The spheres' TV (`tv` on the texel table, `record_sphere_tv`) against its twin
/// `cpu::background_spheres_step::sphere_tv`: a random table, the gradient starting nonzero (TV
/// adds to it), a weight whose per-texel scale is `tv`'s row's 0.7; one map of the table made
/// flat (its within-map differences exactly 0). Tolerance: the `tv` row's (the same kernel).
pub fn check_tv(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    let mut rng = Pcg64::seed_from_u64(seed);
    let (mut t, _, _) = cases(0, seed);
    let map = (t.shape.size * t.shape.size) as usize * TEXEL;
    let flat = [0.3f32, 0.2, 0.5, 0.7];
    for (i, v) in t.table[map..2 * map].iter_mut().enumerate() {
        *v = flat[i % TEXEL];
    }
    let texels = (t.table.len() / TEXEL) as f32;
    let lambda = 0.7 * texels;
    let start: Vec<f32> = (0..t.table.len())
        .map(|_| rng.random_range(-1f32..1.0))
        .collect();
    let bufs = SphereBuffers::upload(gpu, &t)?;
    bufs.grad.write(&start)?;
    let step_record = gpu.zeros::<u32>(1)?;
    let mut b = gpu.batch()?;
    crate::gpu::record_sphere_tv(&mut b, &bufs, &step_record, lambda)?;
    b.submit()?;
    let got = bufs.take_grad()?;
    let mut want = start;
    crate::cpu::background_spheres_step::sphere_tv(&t, &mut want, lambda);
    let mut cmp = Compare::new(1e-6, 1e-4);
    for (i, (x, y)) in got.iter().zip(&want).enumerate() {
        cmp.value(*x as f64, *y as f64, || format!("gradient {i}"));
    }
    Ok(cmp.row(
        "tv_spheres",
        got.len(),
        format!(
            "{} spheres of {}² texels, λ {lambda} (scale 0.7), gradient added to; one map flat",
            t.shape.layers, t.shape.size
        ),
    ))
}
