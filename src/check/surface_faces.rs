//! Exact ownership of level crossings on cell faces, edges and corners (issue 21): `surface_fwd`
//! (kernel and CPU twin) against exact hit counts on rays that pass exactly through lattice points
//! of shared faces, edges and corners, with levels equal to the field there.
//!
//! Grid: 4³ vertices, grid = scene coordinates. Rays move along 1, 2 or 3 axes at once (axis rays,
//! face diagonals through edges, space diagonals through corners) from half-integer starts, so
//! every moving coordinate reaches an integer at the same t: the DDA steps all of those axes at
//! once, and each passage point is a lattice point of a face (1 axis), edge (2) or corner (3).
//! The other coordinates are fixed multiples of ½. Fields: random δ ∈ {0, ±½, ±1} per vertex
//! (axis rays only), or additive δ = X_i + Y_j + Z_k (every ray); along such a ray δ is linear
//! inside each cell, so the exact crossings are the sign changes of the passage values
//! (exact in f64: dyadic values at dyadic points). The levels are the eight most frequent passage
//! values of the field's rays, so most passages put a level exactly on the shared point.
//!
//! Expected rising crossings per (ray, level): transitions − → + of the passage values with zeros
//! dropped (a zero between equal signs is a touch, no crossing), plus one when the ray enters the
//! grid on a zero and leaves it rising (no previous cell: the entering cell decides from the sign
//! after it). The same with δ and τ negated counts the falling crossings (direction check). σα is
//! −10 (α = 0: no early stop) and a = 10⁶ (no truncation), so `hits` is the crossing count.
//! Both backends must match every ray exactly: 0 missed, 0 double-counted.

use super::CheckRow;
use crate::abi::surface_grid::SurfaceGridRef;
use crate::check::surface_fwd::render_gpu;
use crate::cpu::surface_fwd::render;
use crate::gpu::Gpu;
use crate::math::surface::SurfaceParams;
use crate::math::surface::SURF_MAX_LEVELS;
use anyhow::Result;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use std::collections::BTreeMap;

/// Vertices per axis.
const N: usize = 4;
/// Random fields of each kind per check.
const FIELDS: usize = 12;

/// δ at the vertices, x-major.
type Field = Vec<f32>;

/// A test ray: origin, direction (unnormalised, components 0 or ±1), passage points.
struct LatticeRay {
    o: [f32; 3],
    d: [f32; 3],
    /// Points where the moving coordinates are integers, inside the grid box, in ray order.
    passages: Vec<[f64; 3]>,
}

/// Rays moving along the axes of `moving` (1 to 3 axes), every sign combination, moving
/// coordinates starting at −½ + m (or N − ½ − m going down) with m ∈ {0, 1, 2} except the first
/// (m = 0), fixed coordinates in {½, 1, …, N − 3/2}.
fn lattice_rays(moving: &[usize]) -> Vec<LatticeRay> {
    let fixed: Vec<usize> = (0..3).filter(|a| !moving.contains(a)).collect();
    let halves: Vec<f32> = (1..2 * N - 2).map(|k| k as f32 * 0.5).collect();
    let mut out = Vec::new();
    let nm = moving.len();
    for signs in 0..1u32 << nm {
        for offs in 0..3usize.pow(nm as u32 - 1) {
            let m: Vec<usize> = (0..nm)
                .map(|i| {
                    if i == 0 {
                        0
                    } else {
                        (offs / 3usize.pow(i as u32 - 1)) % 3
                    }
                })
                .collect();
            let nf = fixed.len();
            for fx in 0..halves.len().pow(nf as u32) {
                let mut o = [0f32; 3];
                let mut d = [0f32; 3];
                for (i, &a) in moving.iter().enumerate() {
                    let up = signs & (1 << i) == 0;
                    d[a] = if up { 1.0 } else { -1.0 };
                    o[a] = if up {
                        -0.5 + m[i] as f32
                    } else {
                        (N as f32 - 0.5) - m[i] as f32
                    };
                }
                for (j, &a) in fixed.iter().enumerate() {
                    o[a] = halves[(fx / halves.len().pow(j as u32)) % halves.len()];
                }
                let hi = (N - 1) as f64;
                let passages = (0..2 * N + 4)
                    .map(|k| {
                        let u = k as f64 + 0.5;
                        std::array::from_fn(|a| o[a] as f64 + u * d[a] as f64)
                    })
                    .filter(|p: &[f64; 3]| p.iter().all(|&x| (0.0..=hi).contains(&x)))
                    .collect();
                out.push(LatticeRay { o, d, passages });
            }
        }
    }
    out
}

/// Trilinear interpolation of the vertex field at p (exact here: dyadic values and points).
fn field_at(f: &Field, p: [f64; 3]) -> f64 {
    let l = p.map(|x| (x.floor() as usize).min(N - 2));
    let mut v = 0.0;
    for i in 0..8 {
        let b = [(i >> 2) & 1, (i >> 1) & 1, i & 1];
        let mut w = f[((l[0] + b[0]) * N + l[1] + b[1]) * N + l[2] + b[2]] as f64;
        for a in 0..3 {
            let t = p[a] - l[a] as f64;
            w *= if b[a] == 1 { t } else { 1.0 - t };
        }
        v += w;
    }
    v
}

/// Exact rising crossings of the piecewise-linear passage values `w` (δ − τ) along a ray.
fn expected_rising(w: &[f64]) -> u32 {
    let mut n = 0;
    let mut prev = 0.0f64; // last nonzero value; 0 before any
    for &x in w {
        if x == 0.0 {
            continue;
        }
        // From a negative value, or from the grid entry on a zero (nothing before it).
        if x > 0.0 && (prev < 0.0 || (prev == 0.0 && w[0] == 0.0)) {
            n += 1;
        }
        prev = x;
    }
    n
}

/// Tallies of one field against one backend.
#[derive(Default)]
struct Tally {
    rays: usize,
    missed: u64,
    extra: u64,
    first: Option<String>,
}

/// Runs one field through both backends (`gpu` may be absent: CPU twin only).
fn run_field(
    gpu: Option<&Gpu>,
    field: &Field,
    rays: &[LatticeRay],
    zeros: &mut [u64; 2],
    tallies: &mut [Tally; 2],
) -> Result<()> {
    // Levels: the most frequent passage values (ties by value, for determinism).
    let mut freq: BTreeMap<i64, usize> = BTreeMap::new();
    for r in rays {
        for &p in &r.passages {
            *freq
                .entry((field_at(field, p) * 1024.0) as i64)
                .or_default() += 1;
        }
    }
    let mut by_count: Vec<(i64, usize)> = freq.into_iter().collect();
    by_count.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    let levels: Vec<f32> = by_count
        .iter()
        .take(SURF_MAX_LEVELS)
        .map(|&(k, _)| k as f32 / 1024.0)
        .collect();
    for flip in [1.0f32, -1.0] {
        let delta: Vec<f32> = field.iter().map(|&x| flip * x).collect();
        let lv: Vec<f32> = levels.iter().map(|&t| flip * t).collect();
        let n_v = delta.len();
        let links: Vec<i32> = (0..n_v as i32).collect();
        let (opacity, sh) = (vec![-10.0f32; n_v], vec![0.0f32; 27 * n_v]);
        let g = SurfaceGridRef {
            n: N as u32,
            links: &links,
            delta: &delta,
            opacity: &opacity,
            sh: &sh,
            links_checked: false,
        };
        let p = SurfaceParams {
            scale: [1.0; 3],
            offset: [0.0; 3],
            levels: lv.clone(),
            truncation: 1e6.into(),
            stop_thresh: 1e-4,
            background: [1.0; 3],
            spheres: None,
        };
        let ray_buf: Vec<f32> = rays
            .iter()
            .flat_map(|r| r.o.into_iter().chain(r.d))
            .collect();
        let expected: Vec<u32> = rays
            .iter()
            .map(|r| {
                lv.iter()
                    .map(|&tau| {
                        let w: Vec<f64> = r
                            .passages
                            .iter()
                            .map(|&q| flip as f64 * field_at(field, q) - tau as f64)
                            .collect();
                        zeros[0] += w.iter().filter(|&&x| x == 0.0).count() as u64;
                        zeros[1] += w.len() as u64;
                        expected_rising(&w)
                    })
                    .sum()
            })
            .collect();
        let cpu = render(&g, &ray_buf, &p, None)?.0;
        let gpu_out = match gpu {
            Some(gpu) => Some(render_gpu(gpu, &g, &ray_buf, &p, None)?.0),
            None => None,
        };
        for (b, out) in [Some(cpu), gpu_out].iter().enumerate() {
            let Some(out) = out else { continue };
            let t = &mut tallies[b];
            for (i, (o, &e)) in out.iter().zip(&expected).enumerate() {
                t.rays += 1;
                if o.hits != e {
                    t.missed += e.saturating_sub(o.hits) as u64;
                    t.extra += o.hits.saturating_sub(e) as u64;
                    t.first.get_or_insert_with(|| {
                        format!(
                            "ray o {:?} d {:?} (δ×{flip}): hits {} want {e}",
                            rays[i].o, rays[i].d, o.hits
                        )
                    });
                }
            }
        }
    }
    Ok(())
}

/// Face/edge/corner ownership of `surface_fwd` on both backends (CPU twin only when `gpu` is
/// `None`): (passages with a level exactly on them, passages, [cpu, gpu] (rays, missed, extra,
/// first mismatch)).
pub fn face_ownership(gpu: Option<&Gpu>, seed: u64) -> Result<FaceOwnership> {
    let mut rng = Pcg64::seed_from_u64(seed ^ 0xface);
    let axis: Vec<LatticeRay> = (0..3).flat_map(|a| lattice_rays(&[a])).collect();
    let mut all: Vec<LatticeRay> = (0..3).flat_map(|a| lattice_rays(&[a])).collect();
    for m in [&[0, 1][..], &[0, 2], &[1, 2], &[0, 1, 2]] {
        all.extend(lattice_rays(m));
    }
    let mut zeros = [0u64; 2];
    let mut tallies: [Tally; 2] = Default::default();
    for _ in 0..FIELDS {
        let general: Field = (0..N * N * N)
            .map(|_| [-1.0, -0.5, 0.0, 0.5, 1.0][rng.random_range(0..5)])
            .collect();
        run_field(gpu, &general, &axis, &mut zeros, &mut tallies)?;
        let parts: [[f32; N]; 3] = std::array::from_fn(|_| {
            std::array::from_fn(|_| [-0.5, -0.25, 0.0, 0.25, 0.5][rng.random_range(0..5)])
        });
        let additive: Field = (0..N * N * N)
            .map(|v| parts[0][v / (N * N)] + parts[1][(v / N) % N] + parts[2][v % N])
            .collect();
        run_field(gpu, &additive, &all, &mut zeros, &mut tallies)?;
    }
    Ok(FaceOwnership {
        exact_zeros: zeros[0],
        passages: zeros[1],
        backends: tallies.map(|t| (t.rays, t.missed, t.extra, t.first)),
    })
}

/// Result of [`face_ownership`].
#[derive(Debug)]
pub struct FaceOwnership {
    /// (ray, level, passage) triples where the level is exactly the field value.
    pub exact_zeros: u64,
    /// (ray, level, passage) triples.
    pub passages: u64,
    /// Per backend (CPU twin, Vulkan): rays compared, crossings missed, crossings in excess
    /// (double-counted or touches counted), the first mismatching ray.
    pub backends: [(usize, u64, u64, Option<String>); 2],
}

/// The parity row: both backends exact on every ray.
pub fn check(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    let r = face_ownership(Some(gpu), seed)?;
    let [(cr, cm, ce, cf), (gr, gm, ge, gf)] = &r.backends;
    let pass = *cm == 0 && *ce == 0 && *gm == 0 && *ge == 0 && *gr > 0;
    Ok(CheckRow {
        kernel: "surface_faces",
        cases: *gr,
        max_abs: (gm + ge) as f64,
        max_rel: 0.0,
        tolerance: "hits exact (0 missed, 0 double) vs exact counts".into(),
        pass,
        note: format!(
            "{} of {} passages exact zeros; cpu {cr} rays: {cm} missed {ce} extra; gpu: {gm} \
             missed {ge} extra{}{}",
            r.exact_zeros,
            r.passages,
            cf.as_ref()
                .map_or(String::new(), |s| format!("; cpu first: {s}")),
            gf.as_ref()
                .map_or(String::new(), |s| format!("; gpu first: {s}")),
        ),
    })
}
