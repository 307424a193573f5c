//! Parity of the whole draw (`glsl/sample_rays.comp`'s two passes around
//! `glsl/sample_rays_sort.comp`, and pass 1 alone on keys drawn on the host, `gpu::KeyDraw`;
//! uniform, and with a focus on a random fifth of the pixels) with `cpu::sample_rays`: the
//! sorted pixel keys and the importance weights identical
//! (integers: the same draws, the same order), origins identical (a copy of the camera's), unit
//! directions within 4 ulp of 1; rays carried into NDC (`glsl/lib/ndc.glsl`, forward-facing
//! cameras) within that tolerance carried through the map plus [`NDC_OWN_ULP`] (2^-21: the kernel's division, square root and reciprocal may
//! each be off by up to ~1 ulp where the driver does not round them exactly; its products and
//! sums are `precise`), targets within 1 ulp of 1 (a byte over 255).

use super::{CheckRow, Compare};
use crate::abi::buffers::SampleCamera;
use crate::abi::consts::SAMPLE_SORT_RAYS;
use crate::abi::rays::{Focus, NdcProjection, SampleSet, SampledRays};
use crate::cpu::sample_rays::sample_rays;
use crate::cpu::sample_rays_sort;
use crate::data::camera::look_at;
use crate::gpu::{record_sort_runs, Gpu, KeyDraw, TrainViewBuffers};
use anyhow::Result;
use glam::Vec3;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// Tolerance of the directions' components.
pub const DIR_ABS: f64 = 4.0 * f32::EPSILON as f64;
/// The NDC map's own rounding (ulp of max(1, |value|)) beyond what the direction's tolerance
/// carries through it: its nine operations, the divisions and square root each up to ~1 ulp off
/// where the driver does not round them exactly, the quotients d.x/d.z, o.x/n scaled by 2f/W
/// (up to ~4 here).
pub const NDC_OWN_ULP: f64 = 16.0;
/// Tolerance of the targets.
pub const TARGET_ABS: f64 = f32::EPSILON as f64;

/// Views of `w`×`h` random pixels seen by cameras on a sphere of radius 4 looking at the origin
/// with random focal lengths and principal points.
fn views(rng: &mut Pcg64, n_views: usize, w: u32, h: u32) -> (Vec<Vec<u8>>, Vec<SampleCamera>) {
    let images = (0..n_views)
        .map(|_| (0..4 * w * h).map(|_| rng.random::<u8>()).collect())
        .collect();
    let cams = (0..n_views)
        .map(|_| {
            let eye = Vec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(0.2..1.0),
            )
            .normalize()
                * 4.0;
            let m = look_at(eye, Vec3::ZERO, Vec3::Z);
            SampleCamera {
                x_axis: m.x_axis.truncate().to_array(),
                y_axis: m.y_axis.truncate().to_array(),
                z_axis: m.z_axis.truncate().to_array(),
                origin: (eye * (2.0 / 3.0)).to_array(),
                focal: [rng.random_range(20.0..80.0), rng.random_range(20.0..80.0)],
                centre: [
                    rng.random_range(0.3..0.7) * w as f32,
                    rng.random_range(0.3..0.7) * h as f32,
                ],
            }
        })
        .collect();
    (images, cams)
}

/// Cameras of a forward-facing capture in its NDC frame: eyes in the plane z = 4 within ±1 of
/// the axis, looking at the origin; the map's near plane at depth 2.
fn ndc_views(
    rng: &mut Pcg64,
    n_views: usize,
    w: u32,
    h: u32,
) -> (Vec<SampleCamera>, NdcProjection) {
    let cams = (0..n_views)
        .map(|_| {
            let eye = Vec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                4.0,
            );
            let m = look_at(eye, Vec3::ZERO, Vec3::Y);
            SampleCamera {
                x_axis: m.x_axis.truncate().to_array(),
                y_axis: m.y_axis.truncate().to_array(),
                z_axis: m.z_axis.truncate().to_array(),
                origin: eye.to_array(),
                focal: [rng.random_range(30.0..60.0), rng.random_range(30.0..60.0)],
                centre: [0.5 * w as f32, 0.5 * h as f32],
            }
        })
        .collect();
    let proj = NdcProjection {
        near: 2.0,
        sx: 2.0 * 45.0 / w as f32,
        sy: 2.0 * 45.0 / h as f32,
    };
    (cams, proj)
}

/// The NDC map in f64 (`math::ndc::ndc_ray`'s formula).
fn ndc_ray_f64(o: [f64; 3], d: [f64; 3], p: NdcProjection) -> [f64; 6] {
    let (n, sx, sy) = (p.near as f64, p.sx as f64, p.sy as f64);
    let t = -(n + o[2]) / d[2];
    let (ox, oy) = ((o[0] + t * d[0]) / n, (o[1] + t * d[1]) / n);
    let nd = [-sx * (d[0] / d[2] + ox), -sy * (d[1] / d[2] + oy), 2.0];
    let len = (nd[0] * nd[0] + nd[1] * nd[1] + nd[2] * nd[2]).sqrt();
    [
        sx * ox,
        sy * oy,
        -1.0,
        nd[0] / len,
        nd[1] / len,
        nd[2] / len,
    ]
}

/// Per component of the NDC ray of (o, d), how far the direction's tolerance ([`DIR_ABS`] on
/// each component of d) can move it: Σ_k |∂ray_i/∂d_k|·DIR_ABS, the derivatives by f64 central
/// differences.
fn ndc_propagated(o: [f64; 3], d: [f64; 3], p: NdcProjection) -> [f64; 6] {
    let h = 1e-7;
    let mut out = [0.0; 6];
    for k in 0..3 {
        let (mut a, mut b) = (d, d);
        a[k] += h;
        b[k] -= h;
        let (ra, rb) = (ndc_ray_f64(o, a, p), ndc_ray_f64(o, b, p));
        for i in 0..6 {
            out[i] += ((ra[i] - rb[i]) / (2.0 * h)).abs() * DIR_ABS;
        }
    }
    out
}

/// The `check-kernels` row of `sample_rays`, the whole draw: 7 views of 37×23 pixels, a batch of
/// 2·SAMPLE_SORT_RAYS + 1808 rays (two full runs and a partial one, padded in the sort).
pub fn check(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    let mut rng = Pcg64::seed_from_u64(seed);
    let (w, h) = (37, 23);
    let (images, cams) = views(&mut rng, 7, w, h);
    let mut set = SampleSet {
        width: w,
        height: h,
        images: images.iter().map(|i| i.as_slice()).collect(),
        cams,
        focus: Focus::none(),
        ndc: None,
    };
    let n = 2 * SAMPLE_SORT_RAYS as usize + 1808;
    let batch_seed: u64 = rng.random();
    // A fifth of the pixels, scattered, with half of the batch drawn from them: both branches of
    // the draw in one batch.
    let n_pixels = set.n_pixels();
    let focus_pixels: Vec<u32> = (0..n_pixels as u32)
        .filter(|_| rng.random::<f32>() < 0.2)
        .collect();
    let focus = Focus::new(focus_pixels, 0.5, n_pixels)?;

    let (box_cams, (ndc_cams, proj)) = (set.cams.clone(), ndc_views(&mut rng, 7, w, h));

    let mut cmp = Compare::new(0.0, 0.0);
    let mut key_mismatches = 0;
    let mut apart = UlpApart::default();
    // Both ways of drawing the keys, whichever the device uses in training, uniform and focused,
    // and the rays of a forward-facing capture carried into NDC.
    let cases = [KeyDraw::Device, KeyDraw::Host].into_iter().flat_map(|k| {
        [
            (k, Focus::none(), None),
            (k, focus.clone(), None),
            (k, Focus::none(), Some(proj)),
        ]
    });
    for (key_draw, focus, ndc) in cases {
        let focused = !focus.is_none();
        set.focus = focus;
        set.cams = if ndc.is_some() {
            ndc_cams.clone()
        } else {
            box_cams.clone()
        };
        set.ndc = None;
        // The rays before the NDC map, from which the direction's tolerance is carried through it.
        let plain = sample_rays(&set, batch_seed, n)?;
        set.ndc = ndc;
        let want = sample_rays(&set, batch_seed, n)?;
        let name = format!(
            "{key_draw:?}{}{}",
            if focused { " focused" } else { "" },
            if ndc.is_some() { " NDC" } else { "" }
        );
        let id = u64::MAX - 2 * seed - focused as u64;
        let got = draw_on_device(gpu, &set, key_draw, id, batch_seed, n)?;
        let case = Case {
            name: &name,
            got: &got,
            want: &want,
            plain: &plain,
            ndc,
        };
        key_mismatches += compare_keys(&mut cmp, &case);
        compare_rays(&mut cmp, &mut apart, &case);
    }
    cmp.tol.abs = DIR_ABS;
    let UlpApart { dir, ndc, target } = apart;
    let note = format!(
        "{n} rays over 7 views of {w}×{h}, keys drawn on the device and on the host, uniform, \
         with half from a focus of {} pixels, and carried into NDC: keys {} of {} identical; \
         rays at most {dir:.2}, NDC rays {ndc:.2}, targets {target:.2} ulp(1) \
         apart; tolerances: keys and origins exact, directions {:.0} ulp(1), NDC rays the \
         direction's tolerance carried through the map (f64 central differences) + \
         {NDC_OWN_ULP} ulp of max(1, |value|), targets 1 ulp(1)",
        focus.pixels().len(),
        6 * n - key_mismatches,
        6 * n,
        DIR_ABS / f32::EPSILON as f64
    );
    Ok(cmp.row(crate::kernels::sample_rays::INFO.name, 6 * n, note))
}

/// The largest differences between device and twin seen, in ulp(1): directions, NDC rays,
/// targets.
#[derive(Default)]
struct UlpApart {
    dir: f64,
    ndc: f64,
    target: f64,
}

/// One case of the draw: its name in failures, the device's batch, the twin's, the twin's rays
/// before the NDC map (`ndc`: the map, if any).
struct Case<'a> {
    name: &'a str,
    got: &'a SampledRays,
    want: &'a SampledRays,
    plain: &'a SampledRays,
    ndc: Option<NdcProjection>,
}

/// The batch of `n` rays drawn from `set` with `seed` on the device, its keys drawn as
/// `key_draw` (the views uploaded under `id`).
fn draw_on_device(
    gpu: &Gpu,
    set: &SampleSet,
    key_draw: KeyDraw,
    id: u64,
    seed: u64,
    n: usize,
) -> Result<SampledRays> {
    let mut slot = None;
    let views = TrainViewBuffers::ensure(&mut slot, gpu, id, set, n)?;
    views.key_draw = key_draw;
    let mut b = gpu.batch()?;
    views.record_sample(&mut b, set, seed, n)?;
    b.submit()?;
    views.download_batch(n)
}

/// Compare the case's importance weights and keys (exact); returns the keys that differ.
fn compare_keys(cmp: &mut Compare, case: &Case) -> usize {
    let (got, want, name) = (case.got, case.want, case.name);
    if got.weights != want.weights {
        cmp.failures += 1;
        if cmp.first_failure.is_none() {
            cmp.first_failure = Some(format!(
                "{name}: importance weights differ ({} on the device, {} in the twin)",
                got.weights.len(),
                want.weights.len()
            ));
        }
    }
    let mut mismatches = 0;
    for (i, (g, c)) in got.keys.iter().zip(&want.keys).enumerate() {
        cmp.compared += 1;
        if g != c {
            mismatches += 1;
            cmp.failures += 1;
            if cmp.first_failure.is_none() {
                cmp.first_failure = Some(format!("{name} keys, ray {i}: gpu {g:#x} cpu {c:#x}"));
            }
        }
    }
    mismatches
}

/// Compare the case's rays (origins exact, directions within [`DIR_ABS`], NDC rays within the
/// direction's tolerance carried through the map) and targets (within [`TARGET_ABS`]), keeping
/// the largest differences in `apart`.
fn compare_rays(cmp: &mut Compare, apart: &mut UlpApart, case: &Case) {
    let (got, want, name) = (case.got, case.want, case.name);
    let ulp = |g: f64, c: f64| (g - c).abs() / f32::EPSILON as f64;
    for i in 0..want.rays.len() / 6 {
        let tol: [f64; 6] = match case.ndc {
            None => [0.0, 0.0, 0.0, DIR_ABS, DIR_ABS, DIR_ABS],
            Some(p) => {
                let r = &case.plain.rays[6 * i..6 * i + 6];
                let f = |k: usize| r[k] as f64;
                let carried = ndc_propagated([f(0), f(1), f(2)], [f(3), f(4), f(5)], p);
                std::array::from_fn(|k| {
                    carried[k]
                        + NDC_OWN_ULP
                            * f32::EPSILON as f64
                            * want.rays[6 * i + k].abs().max(1.0) as f64
                })
            }
        };
        for (k, &tol) in tol.iter().enumerate() {
            let (g, c) = (got.rays[6 * i + k] as f64, want.rays[6 * i + k] as f64);
            cmp.tol.abs = tol;
            cmp.value(g, c, || format!("{name} keys, ray {i} component {k}"));
            let max = if case.ndc.is_some() {
                &mut apart.ndc
            } else {
                &mut apart.dir
            };
            *max = max.max(ulp(g, c));
        }
        for k in 0..3 {
            let (g, c) = (
                got.targets[3 * i + k] as f64,
                want.targets[3 * i + k] as f64,
            );
            cmp.tol.abs = TARGET_ABS;
            cmp.value(g, c, || format!("{name} keys, ray {i} target {k}"));
            apart.target = apart.target.max(ulp(g, c));
        }
    }
}

/// The `check-kernels` row of `sample_rays_sort`: batches of 2·SAMPLE_SORT_RAYS + 1808 keys (two
/// full runs and a partial one) and of 37 keys, drawn to repeat (a third from 0..50), to reach
/// both ends of the range (0 and all-ones, the padding's value) and to fill it; sorted per run,
/// they must equal the twin's exactly.
pub fn check_sort(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    let mut rng = Pcg64::seed_from_u64(seed);
    let mut cmp = Compare::new(0.0, 0.0);
    let mut cases = 0;
    for n in [2 * SAMPLE_SORT_RAYS as usize + 1808, 37] {
        let keys: Vec<u64> = (0..n)
            .map(|_| match rng.random_range(0..6) {
                0 | 1 => rng.random_range(0..50),
                2 => 0,
                3 => u64::MAX,
                _ => rng.random(),
            })
            .collect();
        let mut want = keys.clone();
        sample_rays_sort(&mut want);
        let src = gpu.upload(&keys)?;
        let dst = gpu.zeros::<u64>(n)?;
        let mut b = gpu.batch()?;
        record_sort_runs(&mut b, &src, &dst, n)?;
        b.submit()?;
        let got: Vec<u64> = dst.download()?;
        for (i, (g, c)) in got.iter().zip(&want).enumerate() {
            cmp.compared += 1;
            if g != c {
                cmp.failures += 1;
                if cmp.first_failure.is_none() {
                    cmp.first_failure =
                        Some(format!("batch of {n}, key {i}: gpu {g:#x} cpu {c:#x}"));
                }
            }
        }
        cases += n;
    }
    let note = format!(
        "{cases} keys in batches of {} and 37, sorted per run of {SAMPLE_SORT_RAYS}: {} differ \
         (tolerance: none, integers)",
        2 * SAMPLE_SORT_RAYS + 1808,
        cmp.failures
    );
    Ok(cmp.row(crate::kernels::sample_rays_sort::INFO.name, cases, note))
}
