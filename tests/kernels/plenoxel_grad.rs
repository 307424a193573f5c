//! Stage-1 backward against central finite differences of an independent f64 forward renderer,
//! on a scene kept away from the discontinuities (σ well above the ReLU threshold, colours well
//! inside the ReLU, no early termination), composited on a learned background (dL/dbg checked
//! too).

use alphasurf::abi::buffers::Background;
use alphasurf::check::{rel_l2, TEST_BACKGROUND};
use alphasurf::grid::{Grid, SH_DIM};
use alphasurf::plenoxel::{CpuPlenoxels, PlenoxelsBackend};
use alphasurf::stage::StageBackend;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// Independent f64 volume renderer of one ray (method.md §2), same sample lattice, composited on
/// `bg`; also returns the sparsity loss before its weight, Σ log(1 + 2σ²) over its samples.
fn render_f64(
    g: &Grid,
    density: &[f64],
    sh: &[f64],
    bg: [f64; 3],
    (ro, rd): ([f64; 3], [f64; 3]),
) -> ([f64; 3], f64) {
    let n = g.res.map(|r| r as f64);
    let scale: [f64; 3] = std::array::from_fn(|i| n[i] / (2.0 * g.radius[i] as f64));
    let offset: [f64; 3] = std::array::from_fn(|i| {
        (0.5 - g.center[i] as f64 / (2.0 * g.radius[i] as f64)) * n[i] - 0.5
    });
    let o: [f64; 3] = std::array::from_fn(|i| ro[i] * scale[i] + offset[i]);
    let dg: [f64; 3] = std::array::from_fn(|i| rd[i] * scale[i]);
    let len = dg.iter().map(|x| x * x).sum::<f64>().sqrt();
    let d = dg.map(|x| x / len);
    let delta = 0.5 / len;
    let (mut t0, mut t1) = (0.0f64, f64::MAX);
    for a in 0..3 {
        let (lo, hi) = (-0.5, n[a] - 0.5);
        if d[a] == 0.0 {
            assert!(o[a] > lo && o[a] < hi);
            continue;
        }
        let (ta, tb) = ((lo - o[a]) / d[a], (hi - o[a]) / d[a]);
        t0 = t0.max(ta.min(tb));
        t1 = t1.min(ta.max(tb));
    }
    let (x, y, z) = (rd[0], rd[1], rd[2]);
    let basis = [
        0.28209479,
        -0.48860251 * y,
        0.48860251 * z,
        -0.48860251 * x,
        1.09254843 * x * y,
        -1.09254843 * y * z,
        0.31539157 * (2.0 * z * z - x * x - y * y),
        -1.09254843 * x * z,
        0.54627422 * (x * x - y * y),
    ];
    let mut color = [0.0f64; 3];
    let mut trans = 1.0f64;
    let mut cauchy = 0.0f64;
    let mut k = 0;
    loop {
        let t = t0 + 0.5 * k as f64;
        if t >= t1 {
            break;
        }
        k += 1;
        let pos: [f64; 3] = std::array::from_fn(|i| (o[i] + d[i] * t).clamp(0.0, n[i] - 1.0));
        let l: [u32; 3] = std::array::from_fn(|i| (pos[i].floor() as u32).min(g.res[i] - 2));
        let p: [f64; 3] = std::array::from_fn(|i| pos[i] - l[i] as f64);
        let mut sigma = 0.0;
        let mut c = [0.0f64; SH_DIM];
        for corner in 0..8u32 {
            let bits = [corner >> 2 & 1, corner >> 1 & 1, corner & 1];
            let w: f64 = (0..3)
                .map(|i| if bits[i] == 1 { p[i] } else { 1.0 - p[i] })
                .product();
            let link = g.links[g.slot(l[0] + bits[0], l[1] + bits[1], l[2] + bits[2])];
            if link < 0 {
                continue;
            }
            sigma += w * density[link as usize];
            for q in 0..SH_DIM {
                c[q] += w * sh[link as usize * SH_DIM + q];
            }
        }
        assert!(sigma > 1e-3, "test scene must stay away from the σ ReLU");
        cauchy += (1.0 + 2.0 * sigma * sigma).ln();
        let alpha = 1.0 - (-sigma * delta).exp();
        for ch in 0..3 {
            let raw: f64 = 0.5 + (0..9).map(|q| basis[q] * c[ch * 9 + q]).sum::<f64>();
            assert!(raw > 1e-3, "test scene must stay away from the colour ReLU");
            color[ch] += trans * alpha * raw;
        }
        trans *= 1.0 - alpha;
    }
    (std::array::from_fn(|ch| color[ch] + trans * bg[ch]), cauchy)
}

/// Central differences of the f64 forward against the CPU backward on a res³ grid with σ in
/// [1, 4], rays entering through the z = −1 face, the loss the batch's mean squared error plus
/// `sparsity`·Σ log(1 + 2σ²) over every ray's samples; `stride` > 1 checks every stride-th parameter. Returns the mean shaded samples per ray.
fn check_against_finite_differences(res: u32, seed: u64, stride: usize, sparsity: f32) -> f64 {
    let mut rng = Pcg64::seed_from_u64(seed);
    let mut g = Grid::sphere(res, [0.0; 3], [1.0; 3], 10.0, 0.0);
    for v in g.density.iter_mut() {
        *v = rng.random_range(1.0..4.0);
    }
    for v in g.sh.iter_mut() {
        *v = rng.random_range(-0.1..0.1);
    }
    let n_rays = 12;
    let mut rays = Vec::new();
    for _ in 0..n_rays {
        let o: [f32; 3] = [
            rng.random_range(-0.5..0.5),
            rng.random_range(-0.5..0.5),
            -3.0,
        ];
        let at: [f32; 3] = [
            rng.random_range(-0.3..0.3),
            rng.random_range(-0.3..0.3),
            0.0,
        ];
        let d: [f32; 3] = std::array::from_fn(|i| at[i] - o[i]);
        let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        rays.extend_from_slice(&o);
        rays.extend(d.map(|x| x / l));
    }
    let targets: Vec<f32> = (0..3 * n_rays)
        .map(|_| rng.random_range(0.2..0.8))
        .collect();
    // No early termination (stop threshold 0), so the loss is smooth in every parameter.
    let mut backend = CpuPlenoxels::new(g.clone());
    backend
        .set_background(Background::new(TEST_BACKGROUND, true))
        .unwrap();
    let grads = backend.gradients(&rays, &targets, 0.0, sparsity).unwrap();
    if sparsity > 0.0 {
        // The sparsity term must weigh in dL/dσ, or the check would not test it.
        let plain = backend.gradients(&rays, &targets, 0.0, 0.0).unwrap();
        let share = rel_l2(&plain.density, &grads.density);
        assert!(share > 0.1, "sparsity's share of dL/dσ only {share:.3}");
    }

    let ray_of = |r: usize| -> ([f64; 3], [f64; 3]) {
        (
            std::array::from_fn(|i| rays[6 * r + i] as f64),
            std::array::from_fn(|i| rays[6 * r + 3 + i] as f64),
        )
    };
    let d64: Vec<f64> = g.density.iter().map(|&x| x as f64).collect();
    let s64: Vec<f64> = g.sh.iter().map(|&x| x as f64).collect();
    let b64 = TEST_BACKGROUND.map(|x| x as f64);
    let loss = |density: &[f64], sh: &[f64], bg: [f64; 3]| -> f64 {
        let (mut total, mut cauchy) = (0.0, 0.0);
        for r in 0..n_rays {
            let (c, s) = render_f64(&g, density, sh, bg, ray_of(r));
            for ch in 0..3 {
                total += (c[ch] - targets[3 * r + ch] as f64).powi(2);
            }
            cauchy += s;
        }
        total / (3 * n_rays) as f64 + sparsity as f64 * cauchy
    };
    let h = 1e-6;
    let fd = |which: usize, i: usize| -> f64 {
        let (mut dp, mut sp, mut bp) = (d64.clone(), s64.clone(), b64);
        let (mut dm, mut sm, mut bm) = (d64.clone(), s64.clone(), b64);
        match which {
            0 => {
                dp[i] += h;
                dm[i] -= h;
            }
            1 => {
                sp[i] += h;
                sm[i] -= h;
            }
            _ => {
                bp[i] += h;
                bm[i] -= h;
            }
        }
        (loss(&dp, &sp, bp) - loss(&dm, &sm, bm)) / (2.0 * h)
    };
    let bg_grad = grads.background.to_vec();
    for (which, analytic) in [(0usize, &grads.density), (1, &grads.sh), (2, &bg_grad)] {
        // Every stride-th parameter, plus every one with a sizeable analytic gradient.
        let max = analytic.iter().fold(0f32, |m, &a| m.max(a.abs()));
        let picked: Vec<usize> = (0..analytic.len())
            .filter(|&i| i % stride == 0 || analytic[i].abs() > 0.3 * max)
            .collect();
        let (mut num, mut den) = (0.0f64, 0.0f64);
        for &i in &picked {
            let n = fd(which, i);
            num += (analytic[i] as f64 - n).powi(2);
            den += n * n;
        }
        let rel = (num / den).sqrt();
        let name = ["dL/dσ", "dL/dSH", "dL/dbg"][which];
        assert!(den > 0.0, "{name}: no gradient at all");
        assert!(
            rel <= 1e-3,
            "{name} at {res}³: relative L2 {rel:.3e} against f64 finite differences ({} parameters)",
            picked.len()
        );
    }
    grads.counts.shaded as f64 / n_rays as f64
}

#[test]
fn cpu_backward_matches_f64_finite_differences() {
    // Few samples per ray: the backward pass replays the forward pass's recorded samples.
    let shaded = check_against_finite_differences(6, 11, 1, 0.0);
    assert!(shaded < 32.0, "{shaded}");
}

#[test]
fn cpu_backward_with_sparsity_matches_f64_finite_differences() {
    // λ such that the sparsity term's dL/dσ (λ·4σ/(1 + 2σ²), σ in [1, 4]) is a sizeable share
    // of the whole (asserted inside).
    check_against_finite_differences(6, 13, 1, 1e-3);
}

#[test]
fn cpu_backward_matches_finite_differences_on_long_rays() {
    // More shaded samples than the replay record holds: the backward pass marches again.
    let shaded = check_against_finite_differences(20, 12, 97, 1e-3);
    assert!(
        shaded > 32.0,
        "rays must shade more than 32 samples, got {shaded}"
    );
}

#[test]
fn tv_gradient_matches_finite_differences() {
    use alphasurf::abi::regularisers::TvChunk;
    use alphasurf::cpu::tv;
    let mut rng = Pcg64::seed_from_u64(5);
    let mut g = Grid::sphere(7, [0.0; 3], [1.0; 3], 1.2, 0.0);
    for v in g.sh.iter_mut() {
        *v = rng.random_range(-1.0..1.0);
    }
    let c = TvChunk {
        res: g.res,
        start: 60,
        count: 150,
        channels: SH_DIM as u32,
        scale: 0.01,
        touch: alphasurf::abi::consts::TOUCH_ALL,
    };
    let mut grad = vec![0.0f32; g.sh.len()];
    let mut touched = vec![0u32; g.allocated()];
    tv(&g.links, &g.sh, &mut grad, &mut touched, &c);
    // Independent f64 TV: forward differences, missing neighbour = equal, mean-free scale.
    let loss = |data: &[f64]| -> f64 {
        let mut total = 0.0;
        for s in c.start as usize..(c.start + c.count) as usize {
            let l = g.links[s];
            if l < 0 {
                continue;
            }
            let v = g.vertex(s);
            for ch in 0..SH_DIM {
                let v0 = data[l as usize * SH_DIM + ch];
                let mut sq = 1e-9;
                for a in 0..3 {
                    let mut nv = v;
                    nv[a] += 1;
                    if nv[a] >= g.res[a] {
                        continue;
                    }
                    let nl = g.links[g.slot(nv[0], nv[1], nv[2])];
                    if nl >= 0 {
                        sq += (data[nl as usize * SH_DIM + ch] - v0).powi(2);
                    }
                }
                total += sq.sqrt();
            }
        }
        total * c.scale as f64
    };
    let base: Vec<f64> = g.sh.iter().map(|&x| x as f64).collect();
    let h = 1e-6;
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for i in 0..g.sh.len() {
        let mut p = base.clone();
        p[i] += h;
        let mut m = base.clone();
        m[i] -= h;
        let fd = (loss(&p) - loss(&m)) / (2.0 * h);
        num += (grad[i] as f64 - fd).powi(2);
        den += fd * fd;
    }
    let rel = (num / den).sqrt();
    assert!(den > 0.0 && rel < 1e-3, "TV gradient relative L2 {rel:.3e}");
}
