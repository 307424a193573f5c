//! Stage-2 surface forward rendering (method.md §3.2, §5): an independent float64 reference
//! renderer against the CPU twin; an analytic planar field (one hit per crossing ray, at the right
//! point); truncated compositing (a = 1, 5, fractional); and the Vulkan parity row.
//!
//! The reference is written from method.md only: it does not call the f32 code. The cells come
//! from sorting every grid-plane crossing of the clipped ray (the cell of a piece is the floor of
//! its midpoint), and each level's crossings in a cell from dense sampling of the trilinear field
//! (plus its extrema, located by bisection on the analytic derivative) and bisection in f64.

use alphasurf::abi::buffers::{SurfCounts, SurfOut};
use alphasurf::abi::consts::SURF_PASS_MIN_T;
use alphasurf::check::surface_blocks::check as blocks_check;
use alphasurf::check::surface_fwd::{check, render_gpu, test_rays, test_scene, SurfaceScene};
use alphasurf::check::TEST_BACKGROUND;
use alphasurf::cpu::surface_blocks::build_blocks;
use alphasurf::cpu::surface_fwd::render;
use alphasurf::gpu::test_gpu;
use alphasurf::math::surface::{Truncation, TruncationCount};
use alphasurf::math::surface_blocks::{
    surf_blocks_per_axis, surf_live_words, SkipRef, SURF_BLOCK_SHIFT_CPU, SURF_BLOCK_SHIFT_VULKAN,
    SURF_BOX_WORDS, SURF_MASK_BITS,
};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// The block edge these tests skip with: the Vulkan backend's (4³; the 8³ of the CPU backend is
/// covered by the parity rows and `math::surface_blocks`' walk test).
const SHIFT: u32 = SURF_BLOCK_SHIFT_VULKAN;

/// A skip structure with 8³ blocks (the CPU backend's).
fn sk8(words: &[u32]) -> SkipRef<'_> {
    SkipRef {
        words,
        shift: SURF_BLOCK_SHIFT_CPU,
    }
}

/// A skip structure with [`SHIFT`].
fn sk(words: &[u32]) -> SkipRef<'_> {
    SkipRef {
        words,
        shift: SHIFT,
    }
}

// ---------------------------------------------------------------------------------------------
// The float64 reference.

/// Samples per cell and level for the crossing search.
const SAMPLES: usize = 64;

/// Reference result of one ray.
#[derive(Clone, Copy, Debug)]
struct RefRay {
    rgb: [f64; 3],
    transmittance: f64,
    hits: u32,
    /// Some crossing or decision lies within f32 rounding of a tie (see `near_degenerate`).
    degenerate: bool,
}

fn trilerp64(c: &[f64; 8], p: [f64; 3]) -> f64 {
    let mut v = 0.0;
    for (i, ci) in c.iter().enumerate() {
        let wx = if i & 4 != 0 { p[0] } else { 1.0 - p[0] };
        let wy = if i & 2 != 0 { p[1] } else { 1.0 - p[1] };
        let wz = if i & 1 != 0 { p[2] } else { 1.0 - p[2] };
        v += wx * wy * wz * ci;
    }
    v
}

fn grad64(c: &[f64; 8], p: [f64; 3]) -> [f64; 3] {
    let mut g = [0.0; 3];
    for (i, ci) in c.iter().enumerate() {
        let b = [(i >> 2) & 1, (i >> 1) & 1, i & 1];
        for (a, ga) in g.iter_mut().enumerate() {
            let mut w = if b[a] == 1 { 1.0 } else { -1.0 };
            for k in 0..3 {
                if k != a {
                    w *= if b[k] == 1 { p[k] } else { 1.0 - p[k] };
                }
            }
            *ga += w * ci;
        }
    }
    g
}

fn sh_basis64(d: [f64; 3]) -> [f64; 9] {
    let [x, y, z] = d;
    [
        0.28209479,
        -0.48860251 * y,
        0.48860251 * z,
        -0.48860251 * x,
        1.09254843 * x * y,
        -1.09254843 * y * z,
        0.31539157 * (2.0 * z * z - x * x - y * y),
        -1.09254843 * x * z,
        0.54627422 * (x * x - y * y),
    ]
}

/// Crossings of f on [0, len]: (s, rising, near-degenerate).
fn crossings64(
    f: &dyn Fn(f64) -> f64,
    fp: &dyn Fn(f64) -> f64,
    len: f64,
) -> Vec<(f64, bool, bool)> {
    let scale = (0..=8)
        .map(|k| f(len * k as f64 / 8.0).abs())
        .fold(0.0, f64::max)
        .max(1e-30);
    let slope = fp(0.0)
        .abs()
        .max(fp(len).abs())
        .max(fp(0.5 * len).abs())
        .max(1e-30);
    // Sample points plus the extrema of f (sign changes of f′, bisected).
    let mut pts: Vec<f64> = (0..=SAMPLES)
        .map(|k| len * k as f64 / SAMPLES as f64)
        .collect();
    let mut degenerate = false;
    let mut extra = Vec::new();
    for w in pts.windows(2) {
        let (mut lo, mut hi) = (w[0], w[1]);
        let (dlo, dhi) = (fp(lo), fp(hi));
        if (dlo < 0.0) != (dhi < 0.0) {
            for _ in 0..80 {
                let mid = 0.5 * (lo + hi);
                if (fp(mid) < 0.0) == (dlo < 0.0) {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            let e = 0.5 * (lo + hi);
            // A tangent touch or near-double root: f at the extremum within rounding of 0.
            if f(e).abs() < 1e-5 * scale {
                degenerate = true;
            }
            extra.push(e);
        }
    }
    pts.extend(extra);
    pts.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let mut out = Vec::new();
    for w in pts.windows(2) {
        let (mut lo, mut hi) = (w[0], w[1]);
        let (flo, fhi) = (f(lo), f(hi));
        // sign(0) counts as positive.
        if (flo < 0.0) == (fhi < 0.0) {
            continue;
        }
        let rising = flo < 0.0;
        for _ in 0..100 {
            let mid = 0.5 * (lo + hi);
            if (f(mid) < 0.0) == (flo < 0.0) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let s = 0.5 * (lo + hi);
        let near = s < 1e-5 || len - s < 1e-5 || fp(s).abs() < 1e-4 * slope || degenerate;
        out.push((s, rising, near));
    }
    if degenerate {
        for o in out.iter_mut() {
            o.2 = true;
        }
        if out.is_empty() {
            out.push((f64::NAN, false, true));
        }
    }
    out
}

/// Renders one ray in f64 by method.md §3.2 and §5, on [`TEST_BACKGROUND`] (`SurfaceScene::params`),
/// with `truncation`'s a and count (per structure: the count restarts at each front crossing of
/// level 0, `sc.levels[0]`).
fn ref_ray(
    sc: &SurfaceScene,
    ro: [f32; 3],
    rd: [f32; 3],
    truncation: Truncation,
    stop: f64,
) -> RefRay {
    let a = truncation.a as f64;
    let per_structure = truncation.count == TruncationCount::Structure;
    let n = sc.n as usize;
    let hi = (n - 1) as f64;
    let og: [f64; 3] =
        std::array::from_fn(|i| ro[i] as f64 * sc.scale[i] as f64 + sc.offset[i] as f64);
    let dg: [f64; 3] = std::array::from_fn(|i| rd[i] as f64 * sc.scale[i] as f64);
    let dl = dg.iter().map(|x| x * x).sum::<f64>().sqrt();
    let dn = dg.map(|x| x / dl);
    let rl = rd.iter().map(|&x| (x as f64).powi(2)).sum::<f64>().sqrt();
    let y = sh_basis64(rd.map(|x| x as f64 / rl));
    let bg = TEST_BACKGROUND.map(|c| c as f64);
    let mut res = RefRay {
        rgb: bg,
        transmittance: 1.0,
        hits: 0,
        degenerate: false,
    };
    // Clip to [0, N−1]³ from t = 0.
    let (mut t_lo, mut t_hi) = (0.0f64, f64::INFINITY);
    for i in 0..3 {
        if dn[i] == 0.0 {
            if og[i] < 0.0 || og[i] > hi {
                return res;
            }
        } else {
            let (ta, tb) = ((0.0 - og[i]) / dn[i], (hi - og[i]) / dn[i]);
            t_lo = t_lo.max(ta.min(tb));
            t_hi = t_hi.min(ta.max(tb));
        }
    }
    if t_lo >= t_hi {
        return res;
    }
    // Pieces between consecutive grid-plane crossings.
    let mut ts = vec![t_lo, t_hi];
    for i in 0..3 {
        if dn[i] != 0.0 {
            for k in 1..n - 1 {
                let t = (k as f64 - og[i]) / dn[i];
                if t > t_lo && t < t_hi {
                    ts.push(t);
                }
            }
        }
    }
    ts.sort_by(|a, b| a.partial_cmp(b).unwrap());
    ts.dedup();
    let pos = |t: f64| -> [f64; 3] { std::array::from_fn(|i| og[i] + t * dn[i]) };
    let allocated = |l: [usize; 3]| -> Option<[usize; 8]> {
        let mut rows = [0usize; 8];
        for (k, r) in rows.iter_mut().enumerate() {
            let v = [l[0] + (k >> 2), l[1] + ((k >> 1) & 1), l[2] + (k & 1)];
            let link = sc.links[(v[0] * n + v[1]) * n + v[2]];
            if link < 0 {
                return None;
            }
            *r = link as usize;
        }
        Some(rows)
    };
    let pieces: Vec<(f64, f64, [usize; 3])> = ts
        .windows(2)
        .map(|w| {
            let m = pos(0.5 * (w[0] + w[1]));
            let l = m.map(|x| (x.floor().max(0.0) as usize).min(n - 2));
            (w[0], w[1], l)
        })
        .collect();
    // A tiny piece whose cell differs in allocation from a neighbour piece: the f32 walk may
    // order or split the cells differently there.
    for (i, p) in pieces.iter().enumerate() {
        if p.1 - p.0 < 1e-5 {
            let me = allocated(p.2).is_some();
            let nb = [i.wrapping_sub(1), i + 1];
            if nb
                .iter()
                .filter_map(|&j| pieces.get(j))
                .any(|q| allocated(q.2).is_some() != me)
            {
                res.degenerate = true;
            }
        }
    }
    // A piece lying within 1e-5 of a grid plane along it (a ray in a face or along an edge): the
    // f32 walk may pick the cell on either side; degenerate when their allocation differs.
    for p in &pieces {
        let m = pos(0.5 * (p.0 + p.1));
        let mut cands = vec![p.2];
        for a in 0..3 {
            let k = m[a].round();
            if (m[a] - k).abs() < 1e-5 && m[a] != k && k >= 1.0 && k <= (n - 2) as f64 {
                let more: Vec<[usize; 3]> = cands
                    .iter()
                    .flat_map(|c| {
                        let (mut lo, mut hi) = (*c, *c);
                        lo[a] = k as usize - 1;
                        hi[a] = k as usize;
                        [lo, hi]
                    })
                    .collect();
                cands = more;
            }
        }
        let me = allocated(p.2).is_some();
        if cands.iter().any(|&c| allocated(c).is_some() != me) {
            res.degenerate = true;
        }
    }
    // Hits in t order, and whether each crosses level 0.
    let mut hits: Vec<(f64, [usize; 8], [f64; 3], bool)> = Vec::new();
    for &(t0, t1, l) in &pieces {
        let Some(rows) = allocated(l) else { continue };
        let c: [f64; 8] = rows.map(|r| sc.delta[r] as f64);
        let local = move |t: f64| -> [f64; 3] {
            let p = pos(t);
            std::array::from_fn(|i| (p[i] - l[i] as f64).clamp(0.0, 1.0))
        };
        let len = t1 - t0;
        let mut cell_hits = Vec::new();
        for (level, &tau) in sc.levels.iter().enumerate() {
            let tau = tau as f64;
            let f = |s: f64| trilerp64(&c, local(t0 + s)) - tau;
            let fp = |s: f64| {
                let g = grad64(&c, local(t0 + s));
                g[0] * dn[0] + g[1] * dn[1] + g[2] * dn[2]
            };
            for (s, rising, near) in crossings64(&f, &fp, len) {
                if near {
                    res.degenerate = true;
                }
                if rising && s.is_finite() {
                    cell_hits.push((t0 + s, level == 0));
                }
            }
        }
        cell_hits.sort_by(|a, b| a.0.partial_cmp(&b.0).unwrap());
        for (t, outer) in cell_hits {
            hits.push((t, rows, local(t), outer));
        }
    }
    // Truncated alpha compositing.
    let mut color = [0.0f64; 3];
    let mut trans = 1.0f64;
    let mut j = 0u32;
    let mut k = 0u32;
    for (_, rows, p, outer) in hits {
        if per_structure && outer {
            k = 0;
        }
        if k as f64 >= a {
            if per_structure && trans >= SURF_PASS_MIN_T as f64 {
                continue;
            }
            break;
        }
        let w: [f64; 8] = std::array::from_fn(|i| {
            (if i & 4 != 0 { p[0] } else { 1.0 - p[0] })
                * (if i & 2 != 0 { p[1] } else { 1.0 - p[1] })
                * (if i & 1 != 0 { p[2] } else { 1.0 - p[2] })
        });
        let sa: f64 = (0..8).map(|i| w[i] * sc.opacity[rows[i]] as f64).sum();
        let alpha = 1.0 - (-sa.max(0.0)).exp();
        let gamma = 0.5 * (1.0 - (std::f64::consts::PI * (a - k as f64).clamp(0.0, 1.0)).cos());
        let at = alpha * gamma;
        for (ch, col) in color.iter_mut().enumerate() {
            let mut v = 0.5;
            for (k, yk) in y.iter().enumerate() {
                let coef: f64 = (0..8)
                    .map(|i| w[i] * sc.sh[rows[i] * 27 + ch * 9 + k] as f64)
                    .sum();
                v += yk * coef;
            }
            *col += trans * at * v.max(0.0);
        }
        trans *= 1.0 - at;
        j += 1;
        k += 1;
        // Early termination within rounding of the threshold.
        if (trans - stop).abs() <= 1e-4 * stop {
            res.degenerate = true;
        }
        if trans < stop {
            break;
        }
    }
    res.rgb = std::array::from_fn(|ch| color[ch] + trans * bg[ch]);
    res.transmittance = trans;
    res.hits = j;
    res
}

fn ref_render(sc: &SurfaceScene, rays: &[f32], truncation: Truncation, stop: f32) -> Vec<RefRay> {
    rays.chunks_exact(6)
        .map(|r| {
            ref_ray(
                sc,
                [r[0], r[1], r[2]],
                [r[3], r[4], r[5]],
                truncation,
                stop as f64,
            )
        })
        .collect()
}

/// A per-structure truncation with parameter `a`.
fn per_structure(a: f32) -> Truncation {
    Truncation {
        a,
        count: TruncationCount::Structure,
    }
}

// ---------------------------------------------------------------------------------------------

/// Both f32 backends (CPU twin, Vulkan) against the f64 reference on the random test scene with
/// random and adversarial rays: rgb and transmittance within 1e-3 and hit counts exact, except
/// rays the reference flags as near-degenerate (counted, capped at 2 %). The fourth pass puts
/// three levels on vertex values of δ (crossings through vertices, culling ties) and 8 levels in
/// all; the last two count the truncation per structure.
#[test]
fn backends_match_f64_reference() {
    let mut total = [0usize; 4];
    for (seed, a, stop, on_vertices, n) in [
        (11u64, 3.5f32.into(), 1e-4f32, false, 16u32),
        (12, 100.0.into(), 1e-3, false, 16),
        (13, 1.5.into(), 0.0, false, 16),
        (14, 100.0.into(), 1e-4, true, 16),
        (15, 100.0.into(), 1e-4, false, 40),
        (16, per_structure(1.5), 1e-4, false, 16),
        (17, per_structure(2.0), 0.0, false, 40),
    ] {
        let a: Truncation = a;
        let mut sc = test_scene(seed, n);
        if on_vertices {
            let k = sc.delta.len();
            sc.levels
                .extend([k / 3, k / 2, 2 * k / 3].map(|i| sc.delta[i]));
        }
        let rays = test_rays(&sc, seed, 1200);
        let p = sc.params(a, stop);
        let blocks = build_blocks(&sc.grid(), &sc.levels, 0.0, SHIFT).unwrap();
        let (cpu, counts) = render(&sc.grid(), &rays, &p, Some(sk(&blocks))).unwrap();
        let (gpu, _, _) = render_gpu(test_gpu(), &sc.grid(), &rays, &p, Some(sk(&blocks))).unwrap();
        let want = ref_render(&sc, &rays, a, stop);
        let n = want.len();
        let hits: u32 = want.iter().map(|w| w.hits).sum();
        let multi = want.iter().filter(|w| w.hits >= 2).count();
        let flagged = want.iter().filter(|w| w.degenerate).count();
        for (backend, got) in [("cpu", &cpu), ("gpu", &gpu)] {
            let mut worst = 0.0f64;
            for (i, (g, w)) in got.iter().zip(&want).enumerate() {
                if w.degenerate {
                    continue;
                }
                let what = || format!("{backend} seed {seed} ray {i}: {g:?} vs {w:?}");
                assert_eq!(g.hits, w.hits, "{}", what());
                for ch in 0..3 {
                    let d = (g.rgb[ch] as f64 - w.rgb[ch]).abs();
                    worst = worst.max(d);
                    assert!(d <= 1e-3, "{}", what());
                }
                let dt = (g.transmittance as f64 - w.transmittance).abs();
                assert!(dt <= 1e-3, "{}", what());
            }
            eprintln!(
                "{backend} seed {seed} {a:?} levels {}: {n} rays, {hits} reference hits ({multi} rays with ≥ 2), {flagged} flagged, max |Δrgb| {worst:.2e}, twin counters {counts:?}",
                sc.levels.len()
            );
        }
        assert!(hits as usize > n / 2, "the scene must produce hits");
        assert!(
            flagged * 50 <= n,
            "{flagged} of {n} rays flagged near-degenerate (cap 2 %)"
        );
        total[0] += n;
        total[1] += flagged;
        total[2] += hits as usize;
        total[3] += counts.blocks_skipped as usize;
    }
    eprintln!("total: {total:?} (rays, flagged, reference hits, blocks skipped)");
    assert!(total[3] > 1000, "the reference rays must skip blocks");
}

// ---------------------------------------------------------------------------------------------
// Block skipping (math::surface_blocks).

/// Rays (grid origin, unit direction) aimed at the skip structure `blocks` of an `n`³ grid with
/// 2^`shift`-cell blocks: along block faces and edges, diagonals through block corners, starting
/// inside a block without levels, in a block face plane and at a grazing angle to one, starting on
/// a block corner.
fn block_rays(
    n: u32,
    blocks: &[u32],
    shift: u32,
    seed: u64,
    count: usize,
) -> Vec<([f32; 3], [f32; 3])> {
    let mut rng = Pcg64::seed_from_u64(seed);
    let nb = surf_blocks_per_axis(n, shift) as usize;
    let bs = (1u32 << shift) as f32;
    let nf = n as f32;
    let bf = |rng: &mut Pcg64| ((rng.random_range(0..=nb) << shift).min(n as usize - 1)) as f32;
    let unit = |d: [f32; 3]| {
        let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        d.map(|x| x / l)
    };
    let masks = &blocks[surf_live_words(n) as usize..][..nb * nb * nb];
    let dead: Vec<usize> = (0..masks.len())
        .filter(|&b| masks[b] & SURF_MASK_BITS == 0)
        .collect();
    (0..count)
        .map(|r| match r % 7 {
            0 => {
                let a = rng.random_range(0..3);
                let mut g = [bf(&mut rng), bf(&mut rng), bf(&mut rng)];
                if r % 14 == 7 {
                    g[(a + 1) % 3] = rng.random_range(0.0..nf - 1.0);
                }
                let mut d = [0.0; 3];
                d[a] = if rng.random() { 1.0 } else { -1.0 };
                g[a] = if d[a] > 0.0 { -2.0 } else { nf + 1.0 };
                (g, d)
            }
            1 => {
                let v = [bf(&mut rng), bf(&mut rng), bf(&mut rng)];
                let d = unit([1.0f32, 1.0, 1.0].map(|s| if rng.random() { s } else { -s }));
                let back = rng.random_range(0.0..2.0 * nf);
                (std::array::from_fn(|i| v[i] - back * d[i]), d)
            }
            2 => {
                let b = if dead.is_empty() {
                    0
                } else {
                    dead[rng.random_range(0..dead.len())]
                };
                let bc = [b / (nb * nb), (b / nb) % nb, b % nb];
                let g = bc.map(|k| (bs * k as f32 + rng.random_range(0.0..bs)).min(nf - 1.0));
                (
                    g,
                    unit(std::array::from_fn(|_| rng.random_range(-1.0..1.0))),
                )
            }
            3 => {
                let a = rng.random_range(0..3);
                let mut g: [f32; 3] = std::array::from_fn(|_| rng.random_range(-3.0..-1.0));
                g[a] = bf(&mut rng);
                let mut d: [f32; 3] = std::array::from_fn(|_| rng.random_range(0.2..1.0));
                d[a] = 0.0;
                (g, unit(d))
            }
            4 => {
                // Grazing: nearly parallel to a block face plane, crossing it far along.
                let a = rng.random_range(0..3);
                let mut g: [f32; 3] = std::array::from_fn(|_| rng.random_range(-3.0..-1.0));
                g[a] = bf(&mut rng) + rng.random_range(-0.01..0.01);
                let mut d: [f32; 3] = std::array::from_fn(|_| rng.random_range(0.2..1.0));
                d[a] = rng.random_range(-1e-3..1e-3);
                (g, unit(d))
            }
            5 => (
                [bf(&mut rng), bf(&mut rng), bf(&mut rng)],
                unit(std::array::from_fn(|_| rng.random_range(-1.0..1.0))),
            ),
            _ => {
                let o = unit(std::array::from_fn(|_| rng.random_range(-1.0..1.0)))
                    .map(|x| 2.0 * nf * x + 0.5 * nf);
                let at: [f32; 3] = std::array::from_fn(|_| rng.random_range(0.0..nf - 1.0));
                (o, unit(std::array::from_fn(|i| at[i] - o[i])))
            }
        })
        .collect()
}

/// Skipping blocks never changes a result: on random scenes (n = 40 and 33, all vertices or 60 %
/// allocated) with random, adversarial and block-aimed rays, both backends give bit-identical
/// outputs without blocks, with all-live masks and with the scene's masks; all-live masks also
/// give identical counters, the scene's masks the same solves, hits and cuts with fewer cells.
#[test]
fn block_skipping_is_exact_and_saves_cells() {
    let gpu = test_gpu();
    for (seed, n, holes) in [(21u64, 40u32, 0.0f32), (22, 33, 0.05)] {
        let mut sc = test_scene(seed, n);
        let mut rng = Pcg64::seed_from_u64(seed);
        for l in sc.links.iter_mut() {
            if rng.random::<f32>() < holes {
                *l = -1;
            }
        }
        let blocks = build_blocks(&sc.grid(), &sc.levels, 0.0, SHIFT).unwrap();
        // Every cell and block live; the allocated box kept.
        let mut live = vec![u32::MAX; blocks.len()];
        let bw = blocks.len() - SURF_BOX_WORDS;
        live[bw..].copy_from_slice(&blocks[bw..]);
        let mut rays = test_rays(&sc, seed, 1500);
        for (g, d) in block_rays(n, &blocks, SHIFT, seed, 1500) {
            rays.extend_from_slice(&sc.grid_to_scene(g));
            rays.extend_from_slice(&d);
        }
        let masks = &blocks[surf_live_words(n) as usize..bw];
        let dead = masks.iter().filter(|&&m| m & SURF_MASK_BITS == 0).count();
        for (a, stop) in [(100.0f32, 1e-4f32), (2.5, 1e-3)] {
            let p = sc.params(a, stop);
            let (base, bc) = render(&sc.grid(), &rays, &p, None).unwrap();
            let (all, ac) = render(&sc.grid(), &rays, &p, Some(sk(&live))).unwrap();
            let (skip, skc) = render(&sc.grid(), &rays, &p, Some(sk(&blocks))).unwrap();
            let (gbase, gbc, _) = render_gpu(gpu, &sc.grid(), &rays, &p, None).unwrap();
            let (gall, gac, _) = render_gpu(gpu, &sc.grid(), &rays, &p, Some(sk(&live))).unwrap();
            let (gskip, gsk, _) =
                render_gpu(gpu, &sc.grid(), &rays, &p, Some(sk(&blocks))).unwrap();
            eprintln!(
                "n {n} holes {holes} a {a}: {dead} of {} blocks dead; counters cpu {bc:?} → {skc:?}, gpu {gbc:?} → {gsk:?}",
                masks.len()
            );
            for (what, b, x, y) in [("cpu", &base, &all, &skip), ("gpu", &gbase, &gall, &gskip)] {
                for (i, ((b, x), y)) in b.iter().zip(x).zip(y).enumerate() {
                    let r = &rays[6 * i..6 * i + 6];
                    assert_eq!(b, x, "{what} all-live n {n} ray {i} {r:?}");
                    assert_eq!(b, y, "{what} skipping n {n} ray {i} {r:?}");
                }
            }
            for (b, x, y) in [(bc, ac, skc), (gbc, gac, gsk)] {
                assert_eq!(b, x);
                assert_eq!([b.solves, b.hits, b.cut], [y.solves, y.hits, y.cut]);
                assert!(y.cells * 3 < b.cells * 2, "cells {} → {}", b.cells, y.cells);
                assert!(
                    y.blocks_skipped > 1000,
                    "{} blocks skipped",
                    y.blocks_skipped
                );
            }
            assert!(bc.hits > 500, "the scene must produce hits");
        }
    }
    let msgs = gpu.validation_messages();
    assert!(msgs.is_empty(), "validation messages: {msgs:#?}");
}

/// A planar field δ = (x − c)·h with level 0 on the only allocated vertices, [8, 16]×[9, 15]², so
/// exactly one block (1, 1, 1) of the 4³ is live: with skipping, each ray crossing the plane inside
/// that patch moving in +x has exactly one hit at the analytic point (SH encodes the position:
/// rgb = 0.5 + (x, y, z)/N), every other ray none, and the output is bit-identical to the walk
/// without blocks, on both backends.
#[test]
fn planar_field_one_live_block() {
    let n = 33u32;
    let nu = n as usize;
    let h = 1.0 / 16.0;
    let c = 12.3f32;
    let y0 = 0.282_094_79f32;
    let mut sc = test_scene(1, n);
    sc.links = vec![-1; nu * nu * nu];
    sc.delta.clear();
    sc.opacity.clear();
    sc.sh.clear();
    sc.levels = vec![0.0];
    for slot in 0..nu * nu * nu {
        let v = [slot / (nu * nu), (slot / nu) % nu, slot % nu];
        if !((8..=16).contains(&v[0]) && (9..=15).contains(&v[1]) && (9..=15).contains(&v[2])) {
            continue;
        }
        let v = v.map(|x| x as f32);
        sc.links[slot] = sc.delta.len() as i32;
        sc.delta.push((v[0] - c) * h);
        sc.opacity.push(40.0);
        let mut sh = [0f32; 27];
        sh[0] = v[0] / (n as f32 * y0);
        sh[9] = v[1] / (n as f32 * y0);
        sh[18] = v[2] / (n as f32 * y0);
        sc.sh.extend_from_slice(&sh);
    }
    // 8³ blocks: the patch lies in one.
    let blocks = build_blocks(&sc.grid(), &sc.levels, 0.0, SURF_BLOCK_SHIFT_CPU).unwrap();
    let words = surf_live_words(n) as usize;
    let masks = &blocks[words..blocks.len() - SURF_BOX_WORDS];
    let live: Vec<usize> = (0..masks.len())
        .filter(|&b| masks[b] & SURF_MASK_BITS != 0)
        .collect();
    assert_eq!(live, vec![(4 + 1) * 4 + 1], "{masks:?}");
    // Live cells: the complete cells of the patch whose x extent holds the plane x = c (δ's
    // range over a cell is its x extent's), x = 12, y, z ∈ [9, 15) — none other.
    let live_cells: Vec<usize> = (0..nu * nu * nu)
        .filter(|&ci| blocks[ci >> 5] & (1 << (ci & 31)) != 0)
        .collect();
    let want: Vec<usize> = (0..nu * nu * nu)
        .filter(|&ci| {
            let v = [ci / (nu * nu), (ci / nu) % nu, ci % nu];
            v[0] == 12 && (9..15).contains(&v[1]) && (9..15).contains(&v[2])
        })
        .collect();
    assert_eq!(live_cells, want);
    let mut rng = Pcg64::seed_from_u64(9);
    let mut rays = Vec::new();
    for r in 0..3000 {
        let (g, at): ([f32; 3], [f32; 3]) = if r % 3 == 0 {
            (
                std::array::from_fn(|_| rng.random_range(-4.0..37.0)),
                std::array::from_fn(|_| rng.random_range(0.0..32.0)),
            )
        } else {
            // Towards the patch, from anywhere around or inside the box.
            let at = [c, rng.random_range(8.5..15.5), rng.random_range(8.5..15.5)];
            (std::array::from_fn(|_| rng.random_range(-4.0..37.0)), at)
        };
        let d: [f32; 3] = std::array::from_fn(|k| at[k] - g[k]);
        let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        rays.extend_from_slice(&sc.grid_to_scene(g));
        rays.extend_from_slice(&d.map(|x| x / l));
    }
    for (g, d) in block_rays(n, &blocks, SURF_BLOCK_SHIFT_CPU, 9, 1000) {
        rays.extend_from_slice(&sc.grid_to_scene(g));
        rays.extend_from_slice(&d);
    }
    let p = sc.params(5.0, 0.0);
    let (cpu0, c0) = render(&sc.grid(), &rays, &p, None).unwrap();
    let (cpu, cc) = render(&sc.grid(), &rays, &p, Some(sk8(&blocks))).unwrap();
    let (gpu0, _, _) = render_gpu(test_gpu(), &sc.grid(), &rays, &p, None).unwrap();
    let (gpu, gc, _) = render_gpu(test_gpu(), &sc.grid(), &rays, &p, Some(sk8(&blocks))).unwrap();
    assert_eq!(cpu0, cpu);
    assert_eq!(gpu0, gpu);
    eprintln!("counters without blocks {c0:?}, with: cpu {cc:?} gpu {gc:?}");
    assert!(cc.cells * 4 < c0.cells, "cells {} → {}", c0.cells, cc.cells);
    let mut hits = 0;
    for (backend, out) in [("cpu", &cpu), ("gpu", &gpu)] {
        for (i, o) in out.iter().enumerate() {
            let r = &rays[6 * i..6 * i + 6];
            let og: [f64; 3] =
                std::array::from_fn(|k| r[k] as f64 * sc.scale[k] as f64 + sc.offset[k] as f64);
            let d: [f64; 3] = std::array::from_fn(|k| r[3 + k] as f64);
            let (mut t_lo, mut t_hi) = (0.0f64, f64::INFINITY);
            for k in 0..3 {
                if d[k] == 0.0 {
                    if og[k] < 0.0 || og[k] > 32.0 {
                        t_hi = -1.0;
                    }
                    continue;
                }
                let (ta, tb) = ((0.0 - og[k]) / d[k], (32.0 - og[k]) / d[k]);
                t_lo = t_lo.max(ta.min(tb));
                t_hi = t_hi.min(ta.max(tb));
            }
            let tp = (c as f64 - og[0]) / d[0];
            let y = og[1] + tp * d[1];
            let z = og[2] + tp * d[2];
            // Crossings within 1e-4 of the patch's edges or of the ray's start are ambiguous, and
            // rays nearly parallel to the plane ill-conditioned (the f32 ray moves the crossing).
            let near = [y - 9.0, y - 15.0, z - 9.0, z - 15.0, tp - t_lo]
                .iter()
                .any(|e| e.abs() < 1e-4);
            if near || d[0].abs() < 0.05 {
                continue;
            }
            let hit = d[0] > 0.0
                && t_lo < t_hi
                && tp >= t_lo
                && tp < t_hi
                && (9.0..15.0).contains(&y)
                && (9.0..15.0).contains(&z);
            let what = || format!("{backend} ray {i}: {o:?}, t {t_lo} {tp} {t_hi}, y {y} z {z}");
            assert_eq!(o.hits, hit as u32, "{}", what());
            if hit {
                hits += 1;
                let [gx, gy, gz] = o.rgb.map(|v| (v as f64 - 0.5) * n as f64);
                assert!(
                    (gx - c as f64).abs() < 2e-4 && (gy - y).abs() < 2e-4 && (gz - z).abs() < 2e-4,
                    "{}: hit at x {gx} y {gy} z {gz}",
                    what()
                );
            } else {
                assert_eq!(o.rgb, TEST_BACKGROUND, "{}", what());
            }
        }
    }
    assert!(hits > 1000, "only {hits} hits");
}

/// δ = (x − c)·h with one level 0: every ray whose clipped segment crosses the plane x = c moving
/// in +x has exactly one hit, rays moving in −x (back faces) or not reaching the plane none. SH
/// encodes the hit position (G = 0.5 + y/N, B = 0.5 + z/N), σα = 40 makes α = 1 in f32, so the
/// colour gives the hit point, which must be the analytic ray/plane intersection.
/// c = 7.3 (inside cells), 7 (on a shared face: counted once, by the entered cell), 0 (on the
/// box's entry face: counted) and 15 = N − 1 (on the outer exit face: dropped, half-open).
#[test]
fn planar_field_one_hit_at_the_right_depth() {
    let n = 16u32;
    let nu = n as usize;
    let h = 1.0 / 16.0;
    let y0 = 0.282_094_79f32;
    let mut crossing = 0;
    let mut on_face = 0;
    for c in [7.3f32, 7.0, 0.0, 15.0] {
        let mut sc = test_scene(1, n);
        sc.links = (0..(nu * nu * nu) as i32).collect();
        sc.delta.clear();
        sc.opacity.clear();
        sc.sh.clear();
        sc.levels = vec![0.0];
        for slot in 0..nu * nu * nu {
            let v = [slot / (nu * nu), (slot / nu) % nu, slot % nu].map(|x| x as f32);
            sc.delta.push((v[0] - c) * h);
            sc.opacity.push(40.0);
            let mut sh = [0f32; 27];
            sh[9] = v[1] / (n as f32 * y0);
            sh[18] = v[2] / (n as f32 * y0);
            sc.sh.extend_from_slice(&sh);
        }
        let mut rng = Pcg64::seed_from_u64(5);
        let mut rays = Vec::new();
        for r in 0..2000 {
            let (g, at): ([f32; 3], [f32; 3]) = if r % 2 == 0 {
                // From anywhere around the box towards a random point inside it.
                (
                    std::array::from_fn(|_| rng.random_range(-4.0..19.0)),
                    std::array::from_fn(|_| rng.random_range(0.0..15.0)),
                )
            } else {
                // Through the faces x = 0 and x = 15 away from their edges, either way.
                let mut a: [f32; 3] = std::array::from_fn(|_| rng.random_range(1.0..14.0));
                let mut b: [f32; 3] = std::array::from_fn(|_| rng.random_range(1.0..14.0));
                a[0] = -2.0;
                b[0] = 0.0;
                if r % 4 == 1 {
                    a[0] = 17.0;
                    b[0] = 15.0;
                }
                (a, b)
            };
            let d: [f32; 3] = std::array::from_fn(|k| at[k] - g[k]);
            let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            rays.extend_from_slice(&sc.grid_to_scene(g));
            rays.extend_from_slice(&d.map(|x| x / l));
        }
        let p = sc.params(5.0, 0.0);
        let blocks = build_blocks(&sc.grid(), &sc.levels, 0.0, SHIFT).unwrap();
        let (cpu, _) = render(&sc.grid(), &rays, &p, Some(sk(&blocks))).unwrap();
        let (gpu, _, _) = render_gpu(test_gpu(), &sc.grid(), &rays, &p, Some(sk(&blocks))).unwrap();
        for (backend, out) in [("cpu", &cpu), ("gpu", &gpu)] {
            for (i, o) in out.iter().enumerate() {
                let r = &rays[6 * i..6 * i + 6];
                let og: [f64; 3] =
                    std::array::from_fn(|k| r[k] as f64 * sc.scale[k] as f64 + sc.offset[k] as f64);
                let d: [f64; 3] = std::array::from_fn(|k| r[3 + k] as f64);
                // Analytic: clipped segment [t_lo, t_hi] of [0, 15]³ from t = 0, plane x = c.
                let (mut t_lo, mut t_hi) = (0.0f64, f64::INFINITY);
                for k in 0..3 {
                    let (ta, tb) = ((0.0 - og[k]) / d[k], (15.0 - og[k]) / d[k]);
                    t_lo = t_lo.max(ta.min(tb));
                    t_hi = t_hi.min(ta.max(tb));
                }
                let tp = (c as f64 - og[0]) / d[0];
                let hit = d[0] > 0.0 && t_lo < t_hi && tp >= t_lo && tp < t_hi;
                // A crossing within 1e-4 voxel of the box boundary is ambiguous in f32, unless it
                // lies exactly on the face (the rules decide it).
                let margin = (tp - t_lo).abs().min((tp - t_hi).abs());
                if t_lo < t_hi && margin > 0.0 && margin < 1e-4 {
                    continue;
                }
                let what = || format!("c {c} {backend} ray {i}: {o:?}, t {t_lo} {tp} {t_hi}");
                assert_eq!(o.hits, hit as u32, "{}", what());
                if hit {
                    crossing += 1;
                    if margin == 0.0 {
                        on_face += 1;
                    }
                    let y = og[1] + tp * d[1];
                    let z = og[2] + tp * d[2];
                    let gy = (o.rgb[1] as f64 - 0.5) * n as f64;
                    let gz = (o.rgb[2] as f64 - 0.5) * n as f64;
                    assert!(o.transmittance == 0.0, "{}", what());
                    assert!(
                        (gy - y).abs() < 2e-4 && (gz - z).abs() < 2e-4,
                        "{}: hit at y {gy} z {gz}, want {y} {z}",
                        what()
                    );
                } else {
                    assert_eq!(o.rgb, TEST_BACKGROUND, "{}", what());
                }
            }
        }
    }
    eprintln!("{crossing} crossing rays over both backends, {on_face} on the box face");
    assert!(crossing > 2000, "only {crossing} crossing rays");
    assert!(
        on_face > 500,
        "only {on_face} crossings on the box entry face"
    );
}

/// An `n`³ grid, every vertex allocated, whose δ depends on x alone (`delta(x)` at the x-th plane
/// of vertices), σα = `sigma`, and colour (0.5 + x/n, 0.2, 0.7) at x from SH band 0.
fn x_scene(n: u32, delta: impl Fn(usize) -> f32, sigma: f32) -> SurfaceScene {
    let nu = n as usize;
    let y0 = 0.282_094_79f32;
    let mut sc = test_scene(1, n);
    sc.links = (0..(nu * nu * nu) as i32).collect();
    sc.delta.clear();
    sc.opacity.clear();
    sc.sh.clear();
    for slot in 0..nu * nu * nu {
        let x = slot / (nu * nu);
        sc.delta.push(delta(x));
        sc.opacity.push(sigma);
        let mut sh = [0f32; 27];
        sh[0] = x as f32 / (n as f32 * y0);
        sh[9] = -0.3 / y0;
        sh[18] = 0.2 / y0;
        sc.sh.extend_from_slice(&sh);
    }
    sc
}

/// One ray of `sc` along +x, slightly tilted, through the middle of a 17³ grid.
fn x_ray(sc: &SurfaceScene) -> Vec<f32> {
    let g = [-1.0f32, 8.3, 7.9];
    let d = [1.0f32, 0.02, -0.01];
    let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let mut rays = sc.grid_to_scene(g).to_vec();
    rays.extend(d.map(|x| x / l));
    rays
}

/// The colour (on [`TEST_BACKGROUND`]), transmittance and hit count, in f64, of [`x_ray`] through
/// an [`x_scene`] of σα giving `alpha`, whose front crossings lie at the given x (each flagged
/// when it crosses level 0), composited with `t`.
fn x_expected(
    crossings: &[(f64, bool)],
    t: Truncation,
    alpha: f64,
    n: u32,
) -> ([f64; 3], f64, u32) {
    let per_structure = t.count == TruncationCount::Structure;
    let a = t.a as f64;
    let (mut col, mut tr, mut k, mut hits) = ([0.0f64; 3], 1.0f64, 0u32, 0u32);
    for &(x, outer) in crossings {
        if per_structure && outer {
            k = 0;
        }
        if k as f64 >= a {
            if per_structure && tr >= SURF_PASS_MIN_T as f64 {
                continue;
            }
            break;
        }
        let u = (a - k as f64).clamp(0.0, 1.0);
        let at = alpha * 0.5 * (1.0 - (std::f64::consts::PI * u).cos());
        let c = [0.5 + x / n as f64, 0.2, 0.7];
        for ch in 0..3 {
            col[ch] += tr * at * c[ch];
        }
        tr *= 1.0 - at;
        k += 1;
        hits += 1;
    }
    let rgb = std::array::from_fn(|ch| col[ch] + tr * TEST_BACKGROUND[ch] as f64);
    (rgb, tr, hits)
}

/// Seven parallel level planes crossed front-facing along a ray: with a = 1 only the first hit
/// contributes, with a = 5 exactly five, and a fractional a blends the last one by γ.
#[test]
fn truncated_compositing() {
    let n = 17u32;
    let h = 1.0 / 16.0;
    let planes = [2.3f64, 4.6, 6.2, 8.5, 10.4, 12.1, 14.7];
    let sigma = 0.9f32;
    let mut sc = x_scene(n, |x| x as f32 * h as f32, sigma);
    sc.levels = planes.iter().map(|&x| (x * h) as f32).collect();
    let rays = x_ray(&sc);
    let alpha = 1.0 - (-(sigma as f64)).exp();
    for a in [1.0f32, 5.0, 2.5, 3.25, 0.5, 8.0] {
        let p = sc.params(a, 0.0);
        let blocks = build_blocks(&sc.grid(), &sc.levels, 0.0, SHIFT).unwrap();
        let (cpu, counts) = render(&sc.grid(), &rays, &p, Some(sk(&blocks))).unwrap();
        let (gpu, gc, _) =
            render_gpu(test_gpu(), &sc.grid(), &rays, &p, Some(sk(&blocks))).unwrap();
        let crossings: Vec<(f64, bool)> = planes.iter().map(|&x| (x, false)).collect();
        let (want, t, used) = x_expected(&crossings, a.into(), alpha, n);
        let cut = u32::from((used as usize) < planes.len());
        for (backend, o, cn) in [("cpu", cpu[0], counts), ("gpu", gpu[0], gc)] {
            assert_eq!(o.hits, used, "{backend} a {a}: {o:?}");
            assert_eq!(cn.hits, used, "{backend} a {a}: counters {cn:?}");
            assert_eq!(cn.cut, cut, "{backend} a {a}: counters {cn:?}");
            for k in 0..3 {
                assert!(
                    (o.rgb[k] as f64 - want[k]).abs() < 2e-5,
                    "{backend} a {a}: {o:?} want {want:?}"
                );
            }
            assert!((o.transmittance as f64 - t).abs() < 2e-6);
        }
    }
}

/// Two structures along a ray, each crossing three nested levels front-facing (δ a tent in x that
/// falls below level 0 between them): counted per ray, a = 2 composites the first structure's
/// outer two levels and ends the ray; counted per structure, each structure gets its own first
/// a hits (the count restarts at the second structure's level-0 crossing), its inner level is
/// passed over, and a fractional a blends each structure's last hit by γ; nearly opaque, the
/// first truncated hit ends the ray (transmittance below SURF_PASS_MIN_T).
#[test]
fn truncation_counted_per_structure() {
    let n = 17u32;
    // δ per x-plane of vertices; levels 0.5, 1.5, 2.5: rising crossings at x = 1.5, 2.5, 3.5
    // (structure 1) and 10.5, 11.5, 12.5 (structure 2).
    let profile = [
        -1.0f32, 0., 1., 2., 3., 2., 1., 0., -1., -1., 0., 1., 2., 3., 2., 1., 0.,
    ];
    let crossings = [
        (1.5f64, true),
        (2.5, false),
        (3.5, false),
        (10.5, true),
        (11.5, false),
        (12.5, false),
    ];
    let mut sc = x_scene(n, |x| profile[x], 0.0);
    sc.levels = vec![0.5, 1.5, 2.5];
    let rays = x_ray(&sc);
    let cases = [
        (0.7f32, Truncation::from(2.0), 2u32, 1u32),
        (0.7, per_structure(2.0), 4, 2),
        (0.7, per_structure(1.5), 4, 2),
        (0.7, per_structure(5.0), 6, 0),
        (0.7, per_structure(1.0), 2, 4),
        // Nearly opaque: T = e^−6 < SURF_PASS_MIN_T after two hits, so the first truncated hit
        // ends the ray as when counting per ray.
        (3.0, per_structure(2.0), 2, 1),
    ];
    for (sigma, t, hits, cut) in cases {
        sc.opacity.iter_mut().for_each(|o| *o = sigma);
        let alpha = 1.0 - (-(sigma as f64)).exp();
        let p = sc.params(t, 0.0);
        let blocks = build_blocks(&sc.grid(), &sc.levels, 0.0, SHIFT).unwrap();
        let (cpu, counts) = render(&sc.grid(), &rays, &p, Some(sk(&blocks))).unwrap();
        let (gpu, gc, _) =
            render_gpu(test_gpu(), &sc.grid(), &rays, &p, Some(sk(&blocks))).unwrap();
        let want = ref_render(&sc, &rays, t, 0.0)[0];
        let (rgb, tr, composited) = x_expected(&crossings, t, alpha, n);
        assert_eq!(composited, hits, "{t:?}");
        assert_eq!(want.hits, hits, "reference {t:?}: {want:?}");
        for (backend, o, cn) in [("cpu", cpu[0], counts), ("gpu", gpu[0], gc)] {
            assert_eq!(o.hits, hits, "{backend} {t:?}: {o:?}");
            assert_eq!(cn.cut, cut, "{backend} {t:?}: counters {cn:?}");
            for ch in 0..3 {
                assert!(
                    (o.rgb[ch] as f64 - rgb[ch]).abs() < 2e-5,
                    "{backend} {t:?}: {o:?} want {rgb:?}"
                );
                // The reference's own crossings (bisection in f64 on the f32 field) agree with
                // the listed ones to rounding.
                assert!(
                    (want.rgb[ch] - rgb[ch]).abs() < 1e-7,
                    "reference {t:?}: {want:?} want {rgb:?}"
                );
            }
            assert!(
                (o.transmittance as f64 - tr).abs() < 2e-6,
                "{backend} {t:?}: {o:?}"
            );
        }
    }
}

/// The parity rows (surface_fwd, surface_blocks) pass on two seeds, with no validation messages.
#[test]
fn gpu_parity_row() {
    let gpu = test_gpu();
    for seed in [1u64, 2] {
        for row in [check(gpu, seed), blocks_check(gpu, seed)] {
            let row = row.unwrap();
            eprintln!("{row:?}");
            assert!(row.pass, "{row:?}");
        }
    }
    let msgs = gpu.validation_messages();
    assert!(msgs.is_empty(), "validation messages: {msgs:#?}");
}

/// Rays that miss (outside the box, zero or NaN direction) are the background with T = 1 and no
/// hits, on both backends; more than 8 levels or a link past the vertex rows is an error, not a panic.
#[test]
fn missing_rays_and_bad_input() {
    let sc = test_scene(3, 8);
    let rays = [
        [5.0f32, 5.0, 5.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, f32::NAN, 1.0, 0.0],
        [f32::INFINITY, 0.0, 0.0, -1.0, 0.0, 0.0],
    ]
    .concat();
    let p = sc.params(5.0, 1e-4);
    let blocks = build_blocks(&sc.grid(), &sc.levels, 0.0, SHIFT).unwrap();
    let (o, counts) = render(&sc.grid(), &rays, &p, Some(sk(&blocks))).unwrap();
    let (og, gc, _) = render_gpu(test_gpu(), &sc.grid(), &rays, &p, Some(sk(&blocks))).unwrap();
    let missed = SurfOut {
        rgb: TEST_BACKGROUND,
        transmittance: 1.0,
        hits: 0,
    };
    assert!(o.iter().chain(&og).all(|x| *x == missed), "{o:?} {og:?}");
    assert_eq!(counts, SurfCounts::default());
    assert_eq!(gc, SurfCounts::default());
    let mut q = sc.params(5.0, 1e-4);
    q.levels = vec![0.0; 9];
    assert!(render(&sc.grid(), &rays, &q, None).is_err());
    assert!(render_gpu(test_gpu(), &sc.grid(), &rays, &q, None).is_err());
    let mut bad = sc.clone();
    bad.links[0] = bad.delta.len() as i32;
    assert!(render(&bad.grid(), &rays, &p, None).is_err());
    assert!(build_blocks(&bad.grid(), &sc.levels, 0.0, SHIFT).is_err());
    // Block masks of the wrong count, too many levels or a negative margin: errors.
    assert!(render(&sc.grid(), &rays, &p, Some(sk(&blocks[1..]))).is_err());
    assert!(render_gpu(test_gpu(), &sc.grid(), &rays, &p, Some(sk(&[0; 2]))).is_err());
    assert!(build_blocks(&sc.grid(), &[0.0; 9], 0.0, SHIFT).is_err());
    assert!(build_blocks(&sc.grid(), &sc.levels, -1.0, SHIFT).is_err());
}

#[test]
fn face_edge_corner_crossings_counted_once_by_the_cpu_twin() {
    let r = alphasurf::check::surface_faces::face_ownership(None, 5).expect("runs");
    let (rays, missed, extra, first) = &r.backends[0];
    assert!(
        *rays > 10_000 && r.exact_zeros > 10_000,
        "{rays} rays, {} exact zeros",
        r.exact_zeros
    );
    assert!(*missed == 0 && *extra == 0, "{r:?} first {first:?}");
}
