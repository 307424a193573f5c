//! Parity of `glsl/dda_walk.comp` with `cpu::dda_walk`, and the ray sets shared by the check, the
//! tests (`tests/kernels/dda.rs`) and `alphasurf bench dda`. Cell sequences (count, indices, checksum of
//! the whole walk) must match exactly; entry/exit t within abs 1e-5 + rel 1e-6 (in practice the
//! twin is bit-exact).

use super::{CheckRow, Compare};
use crate::gpu::Gpu;
use crate::kernels::dda_walk::{Push, INFO};
use anyhow::{ensure, Result};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// Tolerance on entry/exit t.
pub const T_ABS: f64 = 1e-5;
/// Relative part of the t tolerance.
pub const T_REL: f64 = 1e-6;

/// Outputs of one walk run: 2 stats per ray (cells visited, checksum), `k` leading cell indices
/// per ray and their `[t0, t1]` (`2k` per ray).
#[derive(Debug, Clone, PartialEq)]
pub struct DdaOut {
    /// Leading cells recorded per ray.
    pub k: u32,
    /// `[count, checksum]` per ray.
    pub stats: Vec<u32>,
    /// `k` cell indices per ray.
    pub cells: Vec<u32>,
    /// `2k` t values per ray.
    pub ts: Vec<f32>,
}

impl DdaOut {
    /// Total cells visited over all rays.
    pub fn total_cells(&self) -> u64 {
        self.stats.chunks_exact(2).map(|s| s[0] as u64).sum()
    }
}

/// Runs the kernel over `rays` (o, d per ray): outputs and device time in ns.
pub fn run_gpu(gpu: &Gpu, rays: &[[f32; 6]], n: u32, k: u32, t_min: f32) -> Result<(DdaOut, f64)> {
    ensure!(n >= 2, "grid needs at least 2 vertices per axis, got {n}");
    let n_rays = rays.len();
    let ray_buf = gpu.upload(rays)?;
    let stats = gpu.zeros::<u32>(2 * n_rays)?;
    let kk = k as usize * n_rays;
    let cells = gpu.zeros::<u32>(kk.max(1))?;
    let ts = gpu.zeros::<f32>((2 * kk).max(1))?;
    let push = Push {
        rays: ray_buf.address(),
        stats: stats.address(),
        cells: cells.address(),
        ts: ts.address(),
        n_rays: n_rays as u32,
        n,
        k,
        t_min,
    };
    let times = gpu.run_1d(&INFO, &push, n_rays as u32)?;
    let mut cells: Vec<u32> = cells.download()?;
    let mut ts: Vec<f32> = ts.download()?;
    cells.truncate(kk);
    ts.truncate(2 * kk);
    let out = DdaOut {
        k,
        stats: stats.download()?,
        cells,
        ts,
    };
    Ok((out, times.kernel_ns(INFO.name)))
}

/// Runs the CPU twin over `rays`.
pub fn run_cpu(rays: &[[f32; 6]], n: u32, k: u32, t_min: f32) -> DdaOut {
    let n_rays = rays.len();
    let kk = k as usize * n_rays;
    let mut out = DdaOut {
        k,
        stats: vec![0; 2 * n_rays],
        cells: vec![0; kk],
        ts: vec![0.0; 2 * kk],
    };
    crate::cpu::dda_walk(
        bytemuck::cast_slice(rays),
        n,
        k,
        t_min,
        &mut out.stats,
        &mut out.cells,
        &mut out.ts,
    );
    out
}

fn exact(cmp: &mut Compare, gpu: u32, cpu: u32, what: impl FnOnce() -> String) {
    cmp.compared += 1;
    if gpu != cpu {
        cmp.failures += 1;
        if cmp.first_failure.is_none() {
            cmp.first_failure = Some(format!("{}: gpu {gpu} cpu {cpu}", what()));
        }
    }
}

/// Adds the comparison of two runs over the same rays to `cmp`: counts, checksums and recorded
/// cells exactly, t within the tolerance. `label` names the ray set in failure notes.
pub fn compare_into(cmp: &mut Compare, gpu: &DdaOut, cpu: &DdaOut, label: &str) {
    let k = cpu.k as usize;
    for (r, (g, c)) in gpu
        .stats
        .chunks_exact(2)
        .zip(cpu.stats.chunks_exact(2))
        .enumerate()
    {
        exact(cmp, g[0], c[0], || format!("{label} ray {r} count"));
        exact(cmp, g[1], c[1], || format!("{label} ray {r} checksum"));
        for j in 0..(c[0] as usize).min(k) {
            let e = r * k + j;
            exact(cmp, gpu.cells[e], cpu.cells[e], || {
                format!("{label} ray {r} cell {j}")
            });
            for w in 0..2 {
                let (tg, tc) = (gpu.ts[2 * e + w] as f64, cpu.ts[2 * e + w] as f64);
                cmp.value(tg, tc, || format!("{label} ray {r} cell {j} t{w}"));
            }
        }
    }
}

/// Integer and half-integer coordinates around and on the faces of an `n`³ grid.
fn adversarial_coords(n: u32) -> Vec<f32> {
    let m = (n - 1) as f32;
    let mut c = vec![
        -1.0,
        -0.5,
        0.0,
        0.5,
        1.0,
        m * 0.5,
        m - 0.5,
        m,
        m + 0.5,
        m + 1.0,
    ];
    c.sort_by(f32::total_cmp);
    c.dedup();
    c
}

/// Adversarial directions: every integer vector with components in −2..=2 (axis-parallel, on
/// face diagonals, through edges and corners; all crossings exactly representable from the
/// adversarial origins), the signed permutations of (1, 2, 4), and the unit versions of the
/// directions whose nonzero components share one magnitude (ties stay exact after rounding).
pub fn adversarial_dirs() -> Vec<[f32; 3]> {
    let mut dirs = Vec::new();
    for x in -2..=2 {
        for y in -2..=2 {
            for z in -2..=2 {
                if (x, y, z) == (0, 0, 0) {
                    continue;
                }
                let d = [x as f32, y as f32, z as f32];
                dirs.push(d);
                let mags: Vec<i32> = [x, y, z]
                    .into_iter()
                    .filter(|v: &i32| *v != 0)
                    .map(i32::abs)
                    .collect();
                if mags.iter().all(|m| *m == 1) && mags.len() > 1 {
                    dirs.push(crate::math::dda::ray_unit(d));
                }
            }
        }
    }
    for p in [
        [1, 2, 4],
        [1, 4, 2],
        [2, 1, 4],
        [2, 4, 1],
        [4, 1, 2],
        [4, 2, 1],
    ] {
        for s in 0..8 {
            let sg = |b: i32| if s >> b & 1 == 1 { -1.0 } else { 1.0 };
            dirs.push([
                p[0] as f32 * sg(0),
                p[1] as f32 * sg(1),
                p[2] as f32 * sg(2),
            ]);
        }
    }
    dirs
}

/// Every adversarial origin (integer and half-integer coordinates inside, on the faces of and
/// outside the `n`³ box) with every adversarial direction: starts inside and on faces, rays on
/// the outer faces and edges with zero components, corner grazes, misses, negative directions;
/// plus rays with zero, denormal, NaN and infinite components.
pub fn adversarial_rays(n: u32) -> Vec<[f32; 6]> {
    let c = adversarial_coords(n);
    let dirs = adversarial_dirs();
    let mut rays = Vec::with_capacity(c.len().pow(3) * dirs.len());
    for &x in &c {
        for &y in &c {
            for &z in &c {
                for d in &dirs {
                    rays.push([x, y, z, d[0], d[1], d[2]]);
                }
            }
        }
    }
    // Degenerate input: zero, tiny (denormal) and non-finite components all miss or walk alike.
    let h = 0.5 * (n - 1) as f32;
    for bad in [
        0.0,
        1e-40,
        -1e-31,
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
    ] {
        rays.push([h, h, h, bad, bad, bad]);
        rays.push([h, h, h, 1.0, bad, 0.5]);
        rays.push([bad, h, h, 1.0, 0.25, 0.5]);
        rays.push([-1.0, bad, h, 1.0, 1.0, 0.0]);
    }
    rays
}

fn unit_f64(v: [f64; 3]) -> [f32; 3] {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    [(v[0] / l) as f32, (v[1] / l) as f32, (v[2] / l) as f32]
}

fn random_dir(rng: &mut Pcg64) -> [f64; 3] {
    loop {
        let v = [
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        ];
        let l2: f64 = v.iter().map(|x| x * x).sum();
        if l2 > 1e-4 && l2 <= 1.0 {
            return v;
        }
    }
}

/// `count` random unit-direction rays for an `n`³ grid: a fraction `inside` start at a uniform
/// point of the box with a uniform direction; the others start on a sphere of radius `n` around
/// the box centre (outside the box) aimed at a uniform point of the box. The benchmark's rays.
pub fn sphere_rays(count: usize, n: u32, seed: u64, inside: f64) -> Vec<[f32; 6]> {
    let mut rng = Pcg64::seed_from_u64(seed);
    let m = (n - 1) as f64;
    let centre = 0.5 * m;
    (0..count)
        .map(|_| {
            let (o, d) = if rng.random_bool(inside) {
                let o: [f64; 3] = std::array::from_fn(|_| rng.random_range(0.0..m));
                (o, random_dir(&mut rng))
            } else {
                let u = random_dir(&mut rng);
                let l = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
                let o: [f64; 3] = std::array::from_fn(|a| centre + n as f64 * u[a] / l);
                let t: [f64; 3] = std::array::from_fn(|_| rng.random_range(0.0..m));
                (o, std::array::from_fn(|a| t[a] - o[a]))
            };
            let d = unit_f64(d);
            [o[0] as f32, o[1] as f32, o[2] as f32, d[0], d[1], d[2]]
        })
        .collect()
}

/// Random rays for the checks: [`sphere_rays`] where every fourth ray has one or two direction
/// components set to exactly zero, with that origin coordinate inside the slab, on an integer
/// plane half of the time, and now and then on an outer face.
pub fn random_rays(count: usize, n: u32, seed: u64) -> Vec<[f32; 6]> {
    let mut rays = sphere_rays(count, n, seed, 0.25);
    let mut rng = Pcg64::seed_from_u64(seed ^ 0x5eed_dda0);
    let m = (n - 1) as f32;
    for r in rays.iter_mut().skip(3).step_by(4) {
        let zeros = rng.random_range(1..=2);
        let first = rng.random_range(0..3usize);
        for a in (0..zeros).map(|i| (first + i) % 3) {
            r[3 + a] = 0.0;
            r[a] = match rng.random_range(0..4) {
                0 => rng.random_range(0..n) as f32,
                1 => [0.0, m][rng.random_range(0..2)],
                _ => rng.random_range(0.0..m),
            };
        }
        let d = unit_f64([r[3] as f64, r[4] as f64, r[5] as f64]);
        r[3..6].copy_from_slice(&d);
    }
    rays
}

/// `count` fuzz rays for an `n`³ grid: a third arbitrary bit patterns (NaN, infinities,
/// denormals, huge values), a third of magnitudes 1e-8 … 1e12, a third within ±2n of the origin.
pub fn fuzz_rays(count: usize, n: u32, seed: u64) -> Vec<[f32; 6]> {
    let mut rng = Pcg64::seed_from_u64(seed);
    (0..count)
        .map(|i| {
            std::array::from_fn(|_| match i % 3 {
                0 => f32::from_bits(rng.random()),
                1 => rng.random_range(-1.0f32..1.0) * 10f32.powi(rng.random_range(-8..12)),
                _ => rng.random_range(-2.0f32..2.0) * n as f32,
            })
        })
        .collect()
}

/// Adversarial rays on an 8³ grid (all cells recorded), random and fuzz rays on 64³ (first 64
/// cells recorded, every walk checksummed), GPU against the CPU twin.
pub fn check(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    let mut cmp = Compare::new(T_ABS, T_REL);
    let adv = adversarial_rays(8);
    let (g, _) = run_gpu(gpu, &adv, 8, 24, 0.0)?;
    let c = run_cpu(&adv, 8, 24, 0.0);
    compare_into(&mut cmp, &g, &c, "adversarial 8³");
    let mut cells = c.total_cells();
    let rnd = random_rays(20_000, 64, seed);
    let (g, _) = run_gpu(gpu, &rnd, 64, 64, 0.0)?;
    let c = run_cpu(&rnd, 64, 64, 0.0);
    compare_into(&mut cmp, &g, &c, "random 64³");
    cells += c.total_cells();
    let fuzz = fuzz_rays(30_000, 64, seed);
    let (g, _) = run_gpu(gpu, &fuzz, 64, 64, 0.0)?;
    let c = run_cpu(&fuzz, 64, 64, 0.0);
    compare_into(&mut cmp, &g, &c, "fuzz 64³");
    cells += c.total_cells();
    let note = format!(
        "{} adversarial rays on 8³ + {} random + {} fuzz on 64³, {cells} cells; sequences exact",
        adv.len(),
        rnd.len(),
        fuzz.len()
    );
    Ok(cmp.row(INFO.name, adv.len() + rnd.len() + fuzz.len(), note))
}
