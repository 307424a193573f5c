//! Stage-2 backward pass (method.md §3.3–3.4): the CPU twin's gradients of the fused per-ray loss
//! (squared error, entropy LH, depth consistency Lc) with respect to δ, σα, SH and the
//! background (rays composited on a learned one) against central finite differences of a float64
//! forward pass.
//!
//! The f64 forward keeps the discrete structure of the f32 trace (which cells, which levels, in
//! which order) and recomputes everything continuous in f64: each hit's s by Newton's method on the
//! cell's trilinear field minus τ, then α, γ, colour, compositing and the three loss terms. Rays are
//! kept only when every hit is away from the discontinuities (cell faces, tangencies, colour
//! clamps, weight ties for the mode), so the loss is smooth in a neighbourhood of the grid.

// Index loops mirror the formulas; the f64 forward takes the whole ray context.
#![allow(clippy::needless_range_loop, clippy::too_many_arguments)]

use alphasurf::abi::buffers::TrainCounts;
use alphasurf::abi::surface_grid::SurfaceGridRef;
use alphasurf::abi::train::SurfaceLoss;
use alphasurf::check::TEST_BACKGROUND;
use alphasurf::cpu::surface_train::{hit_point, trace_ray, train, SurfaceGrads, Trace, TrainInput};
use alphasurf::math::dda::ray_unit;
use alphasurf::math::sh::sh_basis;
use alphasurf::math::surface::SurfaceParams;
use alphasurf::math::surface::{Truncation, TruncationCount};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

const N: u32 = 6;

struct Scene {
    links: Vec<i32>,
    delta: Vec<f32>,
    opacity: Vec<f32>,
    sh: Vec<f32>,
}

impl Scene {
    fn grid(&self) -> SurfaceGridRef<'_> {
        SurfaceGridRef {
            n: N,
            links: &self.links,
            delta: &self.delta,
            opacity: &self.opacity,
            sh: &self.sh,
            links_checked: false,
        }
    }
}

/// δ rising along +x with gentle bends (levels cross the grid as wavy sheets), or with `layered`
/// rising and falling along x (a ray crosses the levels front-facing in several separate layers),
/// σα in [0.3, 2], SH small around a mid grey.
fn scene(rng: &mut Pcg64, layered: bool) -> Scene {
    let n = N as usize;
    let mut s = Scene {
        links: (0..(n * n * n) as i32).collect(),
        delta: Vec::new(),
        opacity: Vec::new(),
        sh: Vec::new(),
    };
    for x in 0..n {
        for y in 0..n {
            for z in 0..n {
                let (xf, yf, zf) = (x as f32, y as f32, z as f32);
                let along = if layered {
                    0.7 * (1.6 * xf).sin()
                } else {
                    0.35 * (xf - 2.5)
                };
                s.delta
                    .push(along + 0.12 * (0.9 * yf).sin() + 0.08 * (1.3 * zf).cos());
                s.opacity.push(rng.random_range(0.3..2.0));
                for k in 0..27 {
                    let scale = if k % 9 == 0 { 0.3 } else { 0.08 };
                    s.sh.push(rng.random_range(-scale..scale));
                }
            }
        }
    }
    s
}

fn trilerp64(c: &[f64; 8], p: [f64; 3]) -> f64 {
    let mut v = 0.0;
    for (i, ci) in c.iter().enumerate() {
        let w = (0..3)
            .map(|a| {
                if i >> (2 - a) & 1 == 1 {
                    p[a]
                } else {
                    1.0 - p[a]
                }
            })
            .product::<f64>();
        v += w * ci;
    }
    v
}

fn weights64(p: [f64; 3]) -> [f64; 8] {
    std::array::from_fn(|i| {
        (0..3)
            .map(|a| {
                if i >> (2 - a) & 1 == 1 {
                    p[a]
                } else {
                    1.0 - p[a]
                }
            })
            .product()
    })
}

/// The parameters in f64 (perturbed by the finite differences).
struct Params64 {
    delta: Vec<f64>,
    opacity: Vec<f64>,
    sh: Vec<f64>,
    /// The background colour.
    bg: Vec<f64>,
}

/// f64 forward of one traced ray with fixed hit structure; `None` when the ray is near a
/// discontinuity (only checked when `strict`).
fn ray_loss64(
    tr: &Trace,
    rd: [f32; 3],
    target: [f32; 3],
    levels: &[f32],
    a: f64,
    lp: &SurfaceLoss,
    q: &Params64,
    strict: bool,
) -> Option<f64> {
    let dn = tr.dn.map(|v| v as f64);
    let y = sh_basis(ray_unit(rd)).map(|v| v as f64);
    let mut t_acc = 1.0f64;
    let mut color = [0.0f64; 3];
    let mut w = Vec::new();
    let mut depth = Vec::new();
    for j in 0..tr.n {
        let h = &tr.hits[j];
        let c: [f64; 8] = std::array::from_fn(|i| q.delta[h.lk[i] as usize]);
        let tau = levels[h.level as usize] as f64;
        let q0 = h.q0.map(|v| v as f64);
        let pt = |s: f64| -> [f64; 3] { std::array::from_fn(|k| q0[k] + s * dn[k]) };
        let mut s = h.s as f64;
        for _ in 0..30 {
            let f = trilerp64(&c, pt(s)) - tau;
            let e = 1e-7;
            let fp = (trilerp64(&c, pt(s + e)) - trilerp64(&c, pt(s - e))) / (2.0 * e);
            s -= f / fp;
        }
        let len = h.len as f64;
        let p = pt(s);
        let e = 1e-6;
        let fp = (trilerp64(&c, pt(s + e)) - trilerp64(&c, pt(s - e))) / (2.0 * e);
        let range =
            c.iter().copied().fold(f64::MIN, f64::max) - c.iter().copied().fold(f64::MAX, f64::min);
        if strict
            && (s < 0.02 || s > len - 0.02 || fp < 0.05 * range || (s - h.s as f64).abs() > 1e-4)
        {
            return None;
        }
        let wt = weights64(p);
        let sa: f64 = (0..8).map(|i| wt[i] * q.opacity[h.lk[i] as usize]).sum();
        let u = (a - h.count as f64).clamp(0.0, 1.0);
        let gamma = 0.5 * (1.0 - (std::f64::consts::PI * u).cos());
        let at = (1.0 - (-sa.max(0.0)).exp()) * gamma;
        let mut raw = [0.5f64; 3];
        for i in 0..8 {
            let row = h.lk[i] as usize * 27;
            for ch in 0..3 {
                for k in 0..9 {
                    raw[ch] += wt[i] * y[k] * q.sh[row + ch * 9 + k];
                }
            }
        }
        if strict && (raw.iter().any(|&r| r.abs() < 0.02) || sa < 0.05) {
            return None;
        }
        let wj = t_acc * at;
        for ch in 0..3 {
            color[ch] += wj * raw[ch].max(0.0);
        }
        t_acc *= 1.0 - at;
        w.push(wj);
        depth.push((h.t0 as f64 + s) * tr.inv_len as f64);
    }
    let mut l = 0.0;
    for ch in 0..3 {
        let d = color[ch] + t_acc * q.bg[ch] - target[ch] as f64;
        l += 0.5 * lp.grad_scale as f64 * d * d;
    }
    let wsum: f64 = w.iter().sum();
    if wsum > 1e-8 {
        let h: f64 = w
            .iter()
            .filter(|&&x| x > 0.0)
            .map(|&x| -(x / wsum) * (x / wsum).ln())
            .sum();
        l += lp.lambda_h as f64 * h;
    }
    // Lc per structure: a hit whose truncation count is 0 starts one; each structure's hits are
    // pulled to the depth of its largest weight.
    let mut start = 0;
    while start < w.len() {
        let end = (start + 1..w.len())
            .find(|&j| tr.hits[j].count == 0)
            .unwrap_or(w.len());
        let m = (start..end).fold(start, |m, j| if w[j] > w[m] { j } else { m });
        if strict {
            for j in start..end {
                if j != m && (w[m] - w[j] < 1e-3 || (depth[j] - depth[m]).abs() < 1e-3) {
                    return None;
                }
            }
        }
        l += lp.lambda_c as f64
            * depth[start..end]
                .iter()
                .map(|d| (d - depth[m]).abs())
                .sum::<f64>();
        start = end;
    }
    Some(l)
}

#[test]
fn cpu_backward_matches_f64_central_differences() {
    backward_matches_central_differences(2.6.into());
}

/// The same with the truncation counted per structure: γ follows each hit's own count, which
/// restarts at level-0 crossings (some rays of the scene restart it).
#[test]
fn cpu_backward_matches_f64_central_differences_per_structure() {
    backward_matches_central_differences(Truncation {
        a: 1.6,
        count: TruncationCount::Structure,
    });
}

fn backward_matches_central_differences(truncation: Truncation) {
    let mut rng = Pcg64::seed_from_u64(7);
    let sc = scene(&mut rng, truncation.count == TruncationCount::Structure);
    let g = sc.grid();
    let levels = vec![-0.45f32, 0.0, 0.5];
    let p = SurfaceParams {
        scale: [1.0; 3],
        offset: [0.0; 3],
        levels: levels.clone(),
        truncation,
        stop_thresh: 0.0,
        background: TEST_BACKGROUND,
        spheres: None,
    };
    let lp = SurfaceLoss {
        grad_scale: 1.0,
        lambda_h: 0.05,
        lambda_c: 0.02,
    };
    let q = Params64 {
        delta: sc.delta.iter().map(|&v| v as f64).collect(),
        opacity: sc.opacity.iter().map(|&v| v as f64).collect(),
        sh: sc.sh.iter().map(|&v| v as f64).collect(),
        bg: TEST_BACKGROUND.map(|v| v as f64).to_vec(),
    };
    // Rays entering through x = −1 heading roughly +x, kept when smooth.
    let mut rays = Vec::new();
    let mut targets = Vec::new();
    // Importance weights of a focused batch: every per-ray term is ω times the unweighted one.
    let mut weights = Vec::new();
    let mut traces = Vec::new();
    let mut multi = 0;
    while traces.len() < 120 {
        let ro = [-1.0, rng.random_range(0.3..4.7), rng.random_range(0.3..4.7)];
        let rd = ray_unit([
            1.0,
            rng.random_range(-0.4..0.4),
            rng.random_range(-0.4..0.4),
        ]);
        let target = [
            rng.random_range(0.0..1.0),
            rng.random_range(0.0..1.0),
            rng.random_range(0.0..1.0),
        ];
        let mut cnt = TrainCounts::default();
        let tr = trace_ray(&g, ro, rd, &p, None, &mut cnt);
        if tr.n == 0
            || ray_loss64(
                &tr,
                rd,
                target,
                &levels,
                p.truncation.a as f64,
                &lp,
                &q,
                true,
            )
            .is_none()
        {
            continue;
        }
        multi += (tr.n > 1) as usize;
        rays.extend_from_slice(&[ro[0], ro[1], ro[2], rd[0], rd[1], rd[2]]);
        targets.extend_from_slice(&target);
        weights.push(rng.random_range(0.2f32..3.0));
        traces.push((tr, rd, target));
    }
    assert!(multi > 60, "only {multi} rays with several hits");
    let restarts = traces
        .iter()
        .filter(|(tr, _, _)| tr.hits[1..tr.n].iter().any(|h| h.count == 0))
        .count();
    if truncation.count == TruncationCount::Structure {
        assert!(restarts > 5, "only {restarts} rays restart the count");
    } else {
        assert_eq!(restarts, 0);
    }
    // Hit points are inside their cells.
    for (tr, _, _) in &traces {
        for h in &tr.hits[..tr.n] {
            assert!(hit_point(h, tr.dn).iter().all(|v| (0.0..=1.0).contains(v)));
        }
    }
    let rows = sc.delta.len();
    let (mut gd, mut go, mut gs, mut touched) = (
        vec![0f32; rows],
        vec![0f32; rows],
        vec![0f32; 27 * rows],
        vec![0u32; rows],
    );
    let mut gbg = [0f32; 3];
    let (losses, counts) = train(
        &g,
        TrainInput {
            rays: &rays,
            targets: &targets,
            weights: Some(&weights),
        },
        &p,
        &lp,
        None,
        SurfaceGrads {
            delta: &mut gd,
            opacity: &mut go,
            sh: &mut gs,
            touched: &mut touched,
            background: Some(&mut gbg),
        },
    )
    .unwrap();
    assert_eq!(losses.len(), traces.len());
    assert_eq!(counts.guarded, 0, "no hit of these rays should be guarded");
    assert!(losses.iter().any(|l| l.entropy > 0.0) && losses.iter().any(|l| l.consistency > 0.0));

    let total = |q: &Params64| -> f64 {
        traces
            .iter()
            .zip(&weights)
            .map(|((tr, rd, t), &w)| {
                w as f64
                    * ray_loss64(tr, *rd, *t, &levels, p.truncation.a as f64, &lp, q, false)
                        .unwrap()
            })
            .sum()
    };
    let h = 1e-5;
    let mut check = |name: &str, analytic: &[f32], pick: fn(&mut Params64) -> &mut Vec<f64>| {
        let mut q2 = Params64 {
            delta: q.delta.clone(),
            opacity: q.opacity.clone(),
            sh: q.sh.clone(),
            bg: q.bg.clone(),
        };
        let (mut num, mut den, mut checked) = (0.0f64, 0.0f64, 0);
        for i in 0..analytic.len() {
            if analytic[i] == 0.0 && rng.random_range(0..20) != 0 {
                continue;
            }
            let v = pick(&mut q2)[i];
            pick(&mut q2)[i] = v + h;
            let lp_ = total(&q2);
            pick(&mut q2)[i] = v - h;
            let lm = total(&q2);
            pick(&mut q2)[i] = v;
            let fd = (lp_ - lm) / (2.0 * h);
            num += (fd - analytic[i] as f64).powi(2);
            den += fd * fd;
            checked += 1;
        }
        let rel = (num / den).sqrt();
        // The background has 3 values; the grid's groups at least 50 each.
        assert!(
            checked >= analytic.len().min(51) && den > 0.0,
            "{name}: {checked} checked"
        );
        assert!(
            rel <= 1e-3,
            "{name}: relative L2 {rel:.3e} over {checked} values"
        );
        eprintln!("{name}: relative L2 {rel:.3e} over {checked} values");
    };
    check("delta", &gd, |q| &mut q.delta);
    check("opacity", &go, |q| &mut q.opacity);
    check("sh", &gs, |q| &mut q.sh);
    check("background", &gbg, |q| &mut q.bg);
    // Every vertex with a gradient is flagged, in all three groups.
    for i in 0..rows {
        if gd[i] != 0.0 || go[i] != 0.0 || gs[27 * i..27 * i + 27].iter().any(|&v| v != 0.0) {
            assert_eq!(
                touched[i],
                alphasurf::abi::consts::TOUCH_SURFACE,
                "vertex {i} has a gradient but not every group flag"
            );
        }
    }
}
