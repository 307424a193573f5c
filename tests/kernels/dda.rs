//! The DDA walk. The f32 walk (`math::dda`, twin of `glsl/lib/dda.glsl`) against an independent
//! f64 reference that sorts every grid-plane crossing and classifies each piece by its midpoint;
//! tie rules of method.md §5 on hand-made rays; internal invariants; GPU parity.
//!
//! Rule for random rays: the cell sequence must match the reference exactly, except on rays where
//! two crossings of different axes (box faces and `t_min` included) lie within 1e-6·max(1, |t|)
//! of each other — there f32 rounding (≤ ~2e-7·|t| per crossing: one rounding each in k − o, 1/d
//! and the product) may legitimately order them differently.
//! Adversarial rays (exactly representable crossings) allow no exception at all.

use alphasurf::check::dda_walk::{adversarial_rays, fuzz_rays, random_rays, sphere_rays};
use alphasurf::math::dda::{dda_init, ray_box, ray_unit, DdaPiece};

type Piece = ([i32; 3], f64, f64);

/// f64 box clip against [0, n−1]³, written independently of the f32 slab code. Input conventions
/// shared with the walk: non-finite rays miss, components of o and d below 1e-30 count as zero.
fn reference_clip(o: [f64; 3], d: [f64; 3], n: i32, t_min: f64) -> Option<(f64, f64)> {
    if !o.iter().chain(&d).all(|x| x.is_finite()) {
        return None;
    }
    let o = o.map(|x| if x.abs() < 1e-30 { 0.0 } else { x });
    let d = d.map(|x| if x.abs() < 1e-30 { 0.0 } else { x });
    let hi = (n - 1) as f64;
    let (mut t0, mut t1) = (t_min, f64::INFINITY);
    for a in 0..3 {
        if d[a] == 0.0 {
            if o[a] < 0.0 || o[a] > hi {
                return None;
            }
        } else {
            let (p, q) = ((0.0 - o[a]) / d[a], (hi - o[a]) / d[a]);
            t0 = t0.max(p.min(q));
            t1 = t1.min(p.max(q));
        }
    }
    (t0 < t1 && t1.is_finite()).then_some((t0, t1))
}

/// Every grid-plane crossing t (planes 0..n−1 of each axis with d ≠ 0), tagged with its axis.
fn crossings(o: [f64; 3], d: [f64; 3], n: i32) -> Vec<(f64, usize)> {
    let mut v = Vec::new();
    for a in 0..3 {
        if d[a] != 0.0 {
            v.extend((0..n).map(|k| ((k as f64 - o[a]) / d[a], a)));
        }
    }
    v
}

/// f64 reference walk: split [t_enter, t_exit] at every crossing, classify each piece by its
/// midpoint (zero-direction axes by floor(o), clamped to the last cell).
fn reference(o: [f64; 3], d: [f64; 3], n: i32, t_min: f64) -> Vec<Piece> {
    let Some((t0, t1)) = reference_clip(o, d, n, t_min) else {
        return Vec::new();
    };
    let o = o.map(|x| if x.abs() < 1e-30 { 0.0 } else { x });
    let d = d.map(|x| if x.abs() < 1e-30 { 0.0 } else { x });
    let mut ts: Vec<f64> = crossings(o, d, n)
        .into_iter()
        .map(|c| c.0)
        .filter(|t| *t > t0 && *t < t1)
        .collect();
    ts.push(t0);
    ts.push(t1);
    ts.sort_by(f64::total_cmp);
    ts.dedup();
    ts.windows(2)
        .map(|w| {
            let m = 0.5 * (w[0] + w[1]);
            let cell = std::array::from_fn(|a| {
                let x = if d[a] == 0.0 { o[a] } else { o[a] + m * d[a] };
                (x.floor() as i32).clamp(0, n - 2)
            });
            (cell, w[0], w[1])
        })
        .collect()
}

/// Whether two crossings of different axes (or a crossing and t_min) are within the stated
/// window, the only case where random rays may disagree with the reference.
fn near_tie(o: [f64; 3], d: [f64; 3], n: i32, t_min: f64) -> bool {
    let mut c = crossings(o, d, n);
    c.push((t_min, 3));
    c.sort_by(|a, b| a.0.total_cmp(&b.0));
    c.windows(2)
        .any(|w| w[0].1 != w[1].1 && (w[1].0 - w[0].0) <= 1e-6 * w[1].0.abs().max(1.0))
}

fn walk32(r: &[f32; 6], n: i32, t_min: f32) -> Vec<DdaPiece> {
    dda_init([r[0], r[1], r[2]], [r[3], r[4], r[5]], n, t_min).collect()
}

fn as_f64(r: &[f32; 6]) -> ([f64; 3], [f64; 3]) {
    (
        std::array::from_fn(|a| r[a] as f64),
        std::array::from_fn(|a| r[3 + a] as f64),
    )
}

/// Cells equal; t within abs 1e-5 + rel 1e-6 (against the f64 value).
fn matches(w: &[DdaPiece], r: &[Piece]) -> Result<(), String> {
    if w.len() != r.len() {
        return Err(format!("{} cells, reference {}", w.len(), r.len()));
    }
    for (j, (p, q)) in w.iter().zip(r).enumerate() {
        if p.cell != q.0 {
            return Err(format!("cell {j}: {:?}, reference {:?}", p.cell, q.0));
        }
        for (a, b) in [(p.t0 as f64, q.1), (p.t1 as f64, q.2)] {
            if (a - b).abs() > 1e-5 + 1e-6 * b.abs() {
                return Err(format!("cell {j}: t {a} vs reference {b}"));
            }
        }
    }
    Ok(())
}

#[test]
fn adversarial_rays_match_reference_exactly() {
    let mut total = 0usize;
    let mut cells = 0usize;
    for n in [2, 3, 8] {
        let rays = adversarial_rays(n as u32);
        for t_min in [0.0f32, 0.5, 1.0] {
            for r in &rays {
                let (o, d) = as_f64(r);
                let w = walk32(r, n, t_min);
                let rf = reference(o, d, n, t_min as f64);
                if let Err(e) = matches(&w, &rf) {
                    panic!("n {n} t_min {t_min} ray {r:?}: {e}\nwalk {w:?}\nref {rf:?}");
                }
                // Integer directions with components in {1, 2, 4}: every t is exact.
                let exact = d.iter().all(|x| [0.0, 1.0, 2.0, 4.0].contains(&x.abs()));
                if exact {
                    for (p, q) in w.iter().zip(&rf) {
                        assert_eq!((p.t0 as f64, p.t1 as f64), (q.1, q.2), "ray {r:?}");
                    }
                }
                total += 1;
                cells += w.len();
            }
        }
    }
    assert!(
        total > 100_000 && cells > 500_000,
        "{total} rays, {cells} cells"
    );
}

#[test]
fn random_rays_match_reference() {
    let mut mismatched = 0usize;
    let mut near = 0usize;
    let mut total = 0usize;
    for (n, count) in [(4, 20_000), (16, 20_000), (64, 10_000), (256, 4_000)] {
        for (seed, t_min) in [(1u64, 0.0f32), (2, 3.25)] {
            for r in random_rays(count, n as u32, seed * 1000 + n as u64) {
                let (o, d) = as_f64(&r);
                let w = walk32(&r, n, t_min);
                let rf = reference(o, d, n, t_min as f64);
                total += 1;
                if let Err(e) = matches(&w, &rf) {
                    mismatched += 1;
                    assert!(
                        near_tie(o, d, n, t_min as f64),
                        "n {n} ray {r:?} (no near tie): {e}"
                    );
                }
                near += near_tie(o, d, n, t_min as f64) as usize;
            }
        }
    }
    println!("{total} random rays: {near} with near ties, {mismatched} differ from the reference");
    assert!(
        mismatched * 1000 <= total,
        "{mismatched} of {total} mismatched"
    );
}

#[test]
fn walk_invariants_on_random_rays() {
    for n in [2, 5, 64, 256] {
        for r in random_rays(5_000, n as u32, 7 + n as u64) {
            let w = walk32(&r, n, 0.0);
            let o = [r[0], r[1], r[2]];
            let d = [r[3], r[4], r[5]];
            let hi = (n - 1) as f32;
            let [t0, t1] = ray_box(o, d, [0.0; 3], [hi; 3], 0.0);
            if w.is_empty() {
                assert!(t0 >= t1, "ray {r:?} hits [{t0}, {t1}] but walks no cell");
                continue;
            }
            assert_eq!(w[0].t0, t0);
            assert_eq!(w.last().unwrap().t1, t1);
            for p in &w {
                assert!(p.t1 > p.t0);
                assert!(p.cell.iter().all(|c| (0..n - 1).contains(c)), "{r:?} {p:?}");
            }
            for pair in w.windows(2) {
                assert_eq!(pair[0].t1, pair[1].t0, "pieces are contiguous");
                for (a, da) in d.iter().enumerate() {
                    let step = pair[1].cell[a] - pair[0].cell[a];
                    let dir = if *da == 0.0 { 0 } else { da.signum() as i32 };
                    assert!(
                        step == 0 || step == dir,
                        "ray {r:?} steps {step} on axis {a}"
                    );
                }
                assert_ne!(pair[0].cell, pair[1].cell);
            }
        }
    }
}

fn cells_of(o: [f32; 3], d: [f32; 3], n: i32) -> Vec<[i32; 3]> {
    dda_init(o, d, n, 0.0).map(|p| p.cell).collect()
}

#[test]
fn tie_rules() {
    let n = 4;
    // Starting exactly on an interior plane, moving −x: the cell below.
    assert_eq!(cells_of([2.0, 0.5, 0.5], [-1.0, 0.0, 0.0], n)[0], [1, 0, 0]);
    // … moving +x: the cell above.
    assert_eq!(cells_of([2.0, 0.5, 0.5], [1.0, 0.0, 0.0], n)[0], [2, 0, 0]);
    // Zero component on an interior plane: floor.
    assert_eq!(cells_of([-1.0, 2.0, 1.0], [1.0, 0.0, 0.0], n)[0], [0, 2, 1]);
    // On the outer faces y = z = N−1 with zero components: the last cell.
    assert_eq!(
        cells_of([-1.0, 3.0, 3.0], [1.0, 0.0, 0.0], n),
        vec![[0, 2, 2], [1, 2, 2], [2, 2, 2]]
    );
    // On the face x = 0 moving in, and moving out (zero-length: nothing).
    assert_eq!(cells_of([0.0, 1.5, 1.5], [1.0, 0.0, 0.0], n).len(), 3);
    assert!(cells_of([0.0, 1.5, 1.5], [-1.0, 0.0, 0.0], n).is_empty());
    assert!(cells_of([3.0, 1.5, 1.5], [1.0, 1.0, 0.0], n).is_empty());
    // Through edges: both axes step at once, no zero-length piece in between.
    assert_eq!(
        cells_of([-1.0, -1.0, 0.5], [1.0, 1.0, 0.0], n),
        vec![[0, 0, 0], [1, 1, 0], [2, 2, 0]]
    );
    // Through a corner, negative direction.
    assert_eq!(
        cells_of([4.0, 4.0, 4.0], [-1.0, -1.0, -1.0], n),
        vec![[2, 2, 2], [1, 1, 1], [0, 0, 0]]
    );
    // (2, 1, 0): an x crossing every half step in t, coinciding with a y crossing every other.
    let w: Vec<_> = dda_init([0.0, 0.0, 0.5], [2.0, 1.0, 0.0], n, 0.0).collect();
    let cells: Vec<_> = w.iter().map(|p| p.cell).collect();
    assert_eq!(cells, vec![[0, 0, 0], [1, 0, 0], [2, 1, 0]]);
    assert_eq!(
        w.iter().map(|p| p.t1).collect::<Vec<_>>(),
        vec![0.5, 1.0, 1.5]
    );
    // Entering through an outer edge: the corner cell, one piece.
    assert_eq!(
        cells_of([-1.0, 1.0, 1.5], [1.0, 1.0, 0.0], n),
        vec![[0, 2, 1]]
    );
    // Touching the box in one point of an edge or at a corner: a miss.
    assert!(cells_of([-1.0, 2.0, 1.5], [1.0, 1.0, 0.0], n).is_empty());
    assert!(cells_of([-1.0, 2.0, 4.0], [1.0, 1.0, -1.0], n).is_empty());
    // Missing the box; zero component outside its slab.
    assert!(cells_of([-1.0, -1.0, 1.0], [-1.0, 1.0, 0.0], n).is_empty());
    assert!(cells_of([-1.0, -0.5, 1.0], [1.0, 0.0, 0.0], n).is_empty());
    // Inside start: entry t is t_min.
    let w: Vec<_> = dda_init([1.5, 1.5, 1.5], [0.0, 0.0, -1.0], n, 0.25).collect();
    assert_eq!((w[0].cell, w[0].t0, w[0].t1), ([1, 1, 1], 0.25, 0.5));
}

#[test]
fn benchmark_rays_are_sound() {
    let rays = sphere_rays(10_000, 256, 3, 0.2);
    let hits = rays
        .iter()
        .filter(|r| !walk32(r, 256, 0.0).is_empty())
        .count();
    assert!(hits > 9_900, "{hits} of 10000 benchmark rays hit the box");
}

#[test]
fn gpu_parity() {
    let gpu = alphasurf::gpu::test_gpu();
    let row = alphasurf::check::dda_walk::check(gpu, 11).expect("dda_walk check runs");
    println!("{row:?}");
    assert!(row.pass, "{row:?}");
    assert!(
        gpu.validation_messages().is_empty(),
        "{:?}",
        gpu.validation_messages()
    );
}

#[test]
fn fuzz_walks_terminate_in_range() {
    let mut walked = 0usize;
    for (i, n) in [2u32, 3, 17, 64, 299].into_iter().enumerate() {
        let n = n as i32;
        for r in fuzz_rays(40_000, n as u32, 9 + i as u64) {
            let w: Vec<_> = dda_init([r[0], r[1], r[2]], [r[3], r[4], r[5]], n, 0.0)
                .take(3 * n as usize + 10)
                .collect();
            assert!(
                w.len() <= 3 * (n as usize - 1),
                "ray {r:?} n {n}: {} pieces",
                w.len()
            );
            for p in &w {
                assert!(
                    p.cell.iter().all(|c| (0..n - 1).contains(c)),
                    "ray {r:?} n {n}: {p:?}"
                );
                assert!(
                    p.t1 > p.t0 && p.t0.is_finite() && p.t1.is_finite(),
                    "ray {r:?}: {p:?}"
                );
            }
            walked += !w.is_empty() as usize;
        }
    }
    // Coverage floor: 4974 of the 200,000 hit (rays with a direction component ≥ DDA_HUGE miss).
    assert!(walked > 4_500, "{walked} fuzz rays hit the box");
}

/// Rays through exact cell edges and corners with unit directions (`ray_unit`, as the renderers
/// use): every moving coordinate starts at a half-integer and the moving components are equal in
/// magnitude, so those axes reach their planes at the same t by symmetry, although no t is exact.
/// The walk must step them at once (no zero-length or detour cell) and visit exactly the cells of
/// the exact line. Run in both contraction modes (`--features fused`: the twin's a·b + c fused).
#[test]
fn edge_and_corner_rays_step_every_axis_at_once() {
    let (mut rays, mut cells) = (0, 0);
    for n in [4i32, 9] {
        for moving in [&[0usize, 1][..], &[0, 2], &[1, 2], &[0, 1, 2]] {
            let fixed: Vec<usize> = (0..3).filter(|a| !moving.contains(a)).collect();
            for signs in 0..1u32 << moving.len() {
                for m in 0..n {
                    for k in 1..2 * (n - 1) {
                        let mut o = [0f32; 3];
                        let mut d = [0f32; 3];
                        for (i, &a) in moving.iter().enumerate() {
                            let up = signs & (1 << i) == 0;
                            // The first moving axis enters at the box face; the others offset by m.
                            let off = if i == 0 { 0 } else { m } as f32;
                            d[a] = if up { 1.0 } else { -1.0 };
                            o[a] = if up {
                                -0.5 + off
                            } else {
                                (n - 1) as f32 + 0.5 - off
                            };
                        }
                        for &a in &fixed {
                            o[a] = k as f32 * 0.5;
                        }
                        // Exact cells: at u = 0, 1, 2, … every moving coordinate is a half-integer.
                        let want: Vec<[i32; 3]> = (0..2 * n + 2)
                            .map(|u| -> [f64; 3] {
                                std::array::from_fn(|a| o[a] as f64 + u as f64 * d[a] as f64)
                            })
                            .filter(|p: &[f64; 3]| p.iter().all(|&x| x > 0.0 && x < (n - 1) as f64))
                            .map(|p| p.map(|x| (x.floor() as i32).min(n - 2)))
                            .collect();
                        let got = cells_of(o, ray_unit(d), n);
                        assert_eq!(got, want, "n {n} o {o:?} d {d:?}");
                        rays += 1;
                        cells += got.len();
                    }
                }
            }
        }
    }
    assert!(rays > 2000 && cells > 10_000, "{rays} rays, {cells} cells");
}
