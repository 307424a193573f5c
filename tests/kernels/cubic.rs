//! The cell cubic: coefficient formula, f64 oracle against an independent bracket scan,
//! hand-built adversarial cases, the f32 twin against the oracle on every stress class, and the
//! Vulkan kernel against its CPU twin.

use alphasurf::bench::cubic::{score_case, DS_TARGET};
use alphasurf::check::cases::{gen_cases, CaseClass, OracleCase, FLOOR};
use alphasurf::cpu::cubic_solve::CubicCase;
use alphasurf::math::cubic::{
    cell_cubic, crossings, exit_sign, level_ends, solve_crossings, Crossings, CUBIC_MERGE_EPS,
};
use alphasurf::math::cubic_oracle::{eval64, oracle_coefs, oracle_crossings, oracle_solve};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// Trilinear interpolation of the corners (paper order) minus τ at p, in f64 (δ − τ is exact).
fn trilerp64(c: &[f32; 8], p: [f64; 3], tau: f32) -> f64 {
    let mut v = 0.0;
    for (i, &ci) in c.iter().enumerate() {
        let w = |bit: usize, t: f64| if bit == 1 { t } else { 1.0 - t };
        let ci = ci as f64 - tau as f64;
        v += ci * w((i >> 2) & 1, p[0]) * w((i >> 1) & 1, p[1]) * w(i & 1, p[2]);
    }
    v
}

fn case_point(c: &CubicCase, s: f64) -> [f64; 3] {
    [0, 1, 2].map(|k| c.o[k] as f64 + s * c.d[k] as f64)
}

#[test]
fn coefficients_match_direct_trilerp() {
    for class in CaseClass::ALL {
        for c in gen_cases(class, 300, 11) {
            let scale = c
                .corners
                .iter()
                .fold(0.0f64, |m, &v| m.max((v as f64 - c.tau as f64).abs()));
            let orc = oracle_coefs(&c.corners, c.o, c.d, c.tau);
            let cc = cell_cubic(&c.corners, c.o, c.d);
            let [f0, fl] = level_ends(&c.corners, c.o, c.d, c.l, c.tau);
            let ours = [f0 as f64, cc.c1 as f64, cc.c2 as f64, cc.c3 as f64];
            for k in 0..=4 {
                let s = c.l as f64 * k as f64 / 4.0;
                let direct = trilerp64(&c.corners, case_point(&c, s), c.tau);
                let o = eval64(&orc, s);
                assert!(
                    (o - direct).abs() <= 1e-12 * scale.max(1e-30) + 1e-300,
                    "{}: oracle coefficients at s={s}: {o} vs {direct} ({c:?})",
                    class.name()
                );
                let f = eval64(&ours, s);
                assert!(
                    (f - direct).abs() <= 2e-6 * scale,
                    "{}: f32 coefficients at s={s}: {f} vs {direct} ({c:?})",
                    class.name()
                );
            }
            let end = trilerp64(&c.corners, case_point(&c, c.l as f64), c.tau);
            assert!(
                (fl as f64 - end).abs() <= 2e-6 * scale,
                "f(L) {fl} vs {end} ({c:?})"
            );
        }
    }
}

/// Crossings by a dense sign scan (4096 samples) with bisection, independent of the oracle's
/// critical-point split. Returns (s, rising).
fn bracket_scan(c: &[f64; 4], l: f64) -> Vec<(f64, bool)> {
    const N: usize = 4096;
    let s_at = |i: usize| l * i as f64 / N as f64;
    let mut out = Vec::new();
    let mut prev_sign = 0.0f64; // 0: none yet
    let mut zero_at: Option<f64> = None;
    let mut prev_s = 0.0;
    let mut prev_v = eval64(c, 0.0);
    if prev_v == 0.0 {
        zero_at = Some(0.0);
    } else {
        prev_sign = prev_v.signum();
    }
    for i in 1..=N {
        let s = s_at(i);
        let v = eval64(c, s);
        if v == 0.0 {
            zero_at.get_or_insert(s);
        } else {
            if let Some(z) = zero_at.take() {
                if v.signum() != prev_sign {
                    out.push((z, v > 0.0));
                }
            } else if v.signum() != prev_sign {
                let (mut a, mut b) = (prev_s, s);
                for _ in 0..200 {
                    let m = 0.5 * (a + b);
                    if m <= a || m >= b {
                        break;
                    }
                    let fm = eval64(c, m);
                    if fm == 0.0 {
                        a = m;
                        b = m;
                        break;
                    }
                    if fm.signum() == prev_v.signum() {
                        a = m;
                    } else {
                        b = m;
                    }
                }
                out.push((0.5 * (a + b), v > 0.0));
            }
            prev_sign = v.signum();
            prev_v = v;
        }
        prev_s = s;
    }
    out
}

#[test]
fn oracle_agrees_with_bracket_scan() {
    let mut compared = 0;
    for class in CaseClass::ALL {
        for c in gen_cases(class, 1500, 5) {
            let oc = OracleCase::new(&c);
            let scan = bracket_scan(&oc.coefs, oc.l);
            // Every significant oracle crossing is in the scan, and vice versa.
            for x in oc
                .crossings
                .iter()
                .filter(|x| oc.significant_slope(x.slope))
            {
                assert!(
                    scan.iter()
                        .any(|&(s, r)| r == x.rising && (s - x.s).abs() <= 1e-9),
                    "{}: oracle crossing {x:?} not in scan {scan:?} ({c:?})",
                    class.name()
                );
                compared += 1;
            }
            for &(s, r) in &scan {
                let slope = alphasurf::math::cubic_oracle::deriv64(&oc.coefs, s).abs();
                if oc.significant_slope(slope) {
                    assert!(
                        oc.crossings
                            .iter()
                            .any(|x| x.rising == r && (s - x.s).abs() <= 1e-9),
                        "{}: scan crossing {s} not in oracle {:?} ({c:?})",
                        class.name(),
                        oc.crossings
                    );
                }
            }
        }
    }
    assert!(compared > 5000, "too few crossings compared: {compared}");
}

fn one(x: &Crossings) -> (f32, bool) {
    assert_eq!(x.n, 1, "expected one crossing: {x:?}");
    (x.s[0], x.rising[0])
}

#[test]
fn axis_aligned_rays_have_exact_zero_c3() {
    let corners = [0.3f32, -0.2, 0.7, -0.9, -0.4, 0.5, 0.1, 0.8];
    // One zero component: C3 == 0 exactly (quadratic); two: C3 == C2 == 0 (linear).
    for (d, quadratic) in [
        ([0.6f32, 0.8, 0.0], true),
        ([0.0, 0.6, -0.8], true),
        ([1.0, 0.0, 0.0], false),
        ([0.0, 0.0, -1.0], false),
    ] {
        let o = [
            if d[0] < 0.0 { 1.0 } else { 0.0 },
            if d[1] < 0.0 { 1.0 } else { 0.25 },
            if d[2] < 0.0 { 1.0 } else { 0.5 },
        ];
        let cc = cell_cubic(&corners, o, d);
        assert_eq!(cc.c3, 0.0, "C3 for d={d:?}");
        if !quadratic {
            assert_eq!(cc.c2, 0.0, "C2 for d={d:?}");
        }
        // Chord length from o along d.
        let l = (0..3)
            .filter(|&k| d[k] != 0.0)
            .map(|k| {
                if d[k] > 0.0 {
                    (1.0 - o[k]) / d[k]
                } else {
                    -o[k] / d[k]
                }
            })
            .fold(f32::INFINITY, f32::min);
        for tau in [-0.5f32, -0.1, 0.0, 0.2, 0.45] {
            let got = crossings(&corners, o, d, l, tau);
            let want = oracle_crossings(&corners, o, d, l, tau);
            assert_eq!(
                got.n as usize,
                want.len(),
                "d={d:?} τ={tau}: {got:?} vs {want:?}"
            );
            for (k, w) in want.iter().enumerate() {
                assert_eq!(got.rising[k], w.rising);
                assert!((got.s[k] as f64 - w.s).abs() < 1e-5, "{got:?} vs {want:?}");
            }
        }
    }
}

#[test]
fn triple_root_gives_one_net_rising_crossing() {
    // δ = 8(x − ½)(y − ½)(z − ½): corners ±1; along the diagonal from 0, f = 8(s·d − ½)³.
    let corners: [f32; 8] = std::array::from_fn(|i| {
        let sgn = |b: usize| if b == 1 { 1.0 } else { -1.0 };
        sgn((i >> 2) & 1) * sgn((i >> 1) & 1) * sgn(i & 1)
    });
    let dv = 1.0f32 / 3f32.sqrt();
    let d = [dv; 3];
    let l = 3f32.sqrt();
    let x = crossings(&corners, [0.0; 3], d, l, 0.0);
    let root = 0.5 / dv;
    // The critical values sit within rounding of 0 and are snapped: one rising crossing at the
    // first critical point (a triple root in f32 is only located to ~(ε)^(1/3) voxel).
    let (s, rising) = one(&x);
    assert!(rising, "{x:?}");
    assert!(
        (s - root).abs() < 1e-2,
        "near the triple root {root}: {x:?}"
    );
    let o = oracle_crossings(&corners, [0.0; 3], d, l, 0.0);
    assert!(o.len() % 2 == 1 && o[0].rising, "oracle: {o:?}");
}

#[test]
fn root_exactly_at_entry_is_owned_by_the_entering_cell() {
    // The ray enters on the edge x = 0, y = 0 whose corners equal τ.
    let tau = 0.25f32;
    let mut corners = [0.9f32, -0.3, 0.6, 0.4, 0.8, 0.7, -0.2, 0.5];
    corners[0] = tau;
    corners[1] = tau;
    let o = [0.0, 0.0, 0.37];
    let d = [0.6, 0.64, -0.48];
    let [f0, _] = level_ends(&corners, o, d, 0.5, tau);
    assert_eq!(f0, 0.0);
    let x = crossings(&corners, o, d, 0.5, tau);
    let (s, rising) = one(&x);
    assert_eq!(s, 0.0);
    let after = trilerp64(&corners, [0.006, 0.0064, 0.37 - 0.0048], tau);
    assert_eq!(rising, after > 0.0);
    // With no previous cell (`before` unknown) a zero at the entry is a crossing at 0 in the
    // direction f leaves, as in the oracle.
    assert_eq!(oracle_crossings(&corners, o, d, 0.5, tau).len(), 1);
    // Told the sign before the entry point (the previous cell's exit sign), the cell counts the
    // zero only when f changes sign through it: a touch is no crossing.
    let cc = cell_cubic(&corners, o, d);
    let ends = level_ends(&corners, o, d, 0.5, tau);
    let leave = if rising { 1.0 } else { -1.0 };
    let x = solve_crossings(cc, ends, 0.5, -leave);
    assert_eq!((x.n, x.s[0], x.rising[0]), (1, 0.0, rising), "{x:?}");
    let x = solve_crossings(cc, ends, 0.5, leave);
    assert_eq!(x.n, 0, "touch counted: {x:?}");
    assert_eq!(exit_sign(&x, ends[0], leave), leave);
}

#[test]
fn exit_sign_is_the_sign_the_walk_ends_on() {
    // δ = x − ½ along +x: one rising crossing, then positive.
    let corners = [-0.5f32, -0.5, -0.5, -0.5, 0.5, 0.5, 0.5, 0.5];
    let (o, d) = ([0.0, 0.3, 0.6], [1.0, 0.0, 0.0]);
    for (tau, want) in [(0.0f32, 1.0f32), (-0.75, 1.0), (0.75, -1.0), (0.5, -1.0)] {
        let ends = level_ends(&corners, o, d, 1.0, tau);
        let x = solve_crossings(cell_cubic(&corners, o, d), ends, 1.0, 0.0);
        assert_eq!(exit_sign(&x, ends[0], 0.0), want, "τ {tau}: {x:?}");
    }
    // A segment on the level everywhere passes `before` on.
    let flat = [0.25f32; 8];
    let ends = level_ends(&flat, o, d, 1.0, 0.25);
    let x = solve_crossings(cell_cubic(&flat, o, d), ends, 1.0, -1.0);
    assert_eq!((x.n, exit_sign(&x, ends[0], -1.0)), (0, -1.0));
}

#[test]
fn root_exactly_at_exit_belongs_to_the_next_cell() {
    // Axis-aligned ray along +x leaving through the edge x = 1, y = 0 whose corners are at the
    // level (τ = 0): f(L) = 0 exactly, so the crossing is not this cell's.
    let corners = [-0.5f32, -0.25, 0.5, 0.75, 0.0, 0.0, 0.5, 0.25];
    let (o, d) = ([0.0, 0.0, 0.3], [1.0, 0.0, 0.0]);
    let [f0, fl] = level_ends(&corners, o, d, 1.0, 0.0);
    assert!(f0 < 0.0);
    assert_eq!(fl, 0.0);
    let x = crossings(&corners, o, d, 1.0, 0.0);
    assert_eq!(x.n, 0, "{x:?}");
    assert!(oracle_crossings(&corners, o, d, 1.0, 0.0).is_empty());
    // Raising the level a little moves the crossing inside: then it is this cell's.
    let x = crossings(&corners, o, d, 1.0, -0.01);
    let (s, rising) = one(&x);
    // δ = −0.425·(1 − x) along y = 0, z = 0.3.
    assert!(rising && (s - (1.0 - 0.01 / 0.425)).abs() < 1e-5, "{x:?}");
}

#[test]
fn shared_face_crossing_counted_once() {
    // Two cells along x sharing the face x = 1, δ = x − 1 (+ y, z terms) so the level τ = 0 lies
    // on the shared face along the ray's path at y = z = const.
    let field = |x: f32, y: f32, z: f32| (x - 1.0) * (1.0 + 0.5 * y) + 0.0 * z;
    let cell = |x0: f32| -> [f32; 8] {
        std::array::from_fn(|i| {
            field(
                x0 + ((i >> 2) & 1) as f32,
                ((i >> 1) & 1) as f32,
                (i & 1) as f32,
            )
        })
    };
    let (a, b) = (cell(0.0), cell(1.0));
    let mut rng = Pcg64::seed_from_u64(3);
    for _ in 0..2000 {
        // Exit point of cell A on its face x = 1, direction with dx > 0.
        let q = [
            1.0f32,
            rng.random_range(0.05..0.95),
            rng.random_range(0.05..0.95),
        ];
        let d: [f32; 3] = [
            rng.random_range(0.2..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        ];
        let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let d = d.map(|v| v / n);
        let la: f32 = rng.random_range(0.01..0.04);
        let oa = [0, 1, 2].map(|k| (q[k] - la * d[k]).clamp(0.0, 1.0));
        // Cell B entered at q (shifted by −1 in x), leaving after lb.
        let ob = [0.0, q[1], q[2]];
        let lb: f32 = rng.random_range(0.01..0.04);
        let xa = crossings(&a, oa, d, la, 0.0);
        let xb = crossings(&b, ob, d, lb, 0.0);
        assert_eq!(
            xa.n + xb.n,
            1,
            "counted once: A {xa:?} B {xb:?} (d {d:?} q {q:?})"
        );
        assert_eq!(xb.n, 1, "the entering cell owns it");
        assert_eq!(xb.s[0], 0.0);
        assert!(xb.rising[0]);
    }
}

#[test]
fn tangent_touch_is_no_hit() {
    // A cell: δ = 4(x − ½)(y − ½) (corners ±1), level 0, ray along the diagonal x = y in the
    // plane z = ½: f(s) = 4(s·d − ½)² touches 0 at s = ½/d without crossing.
    let corners: [f32; 8] = std::array::from_fn(|i| {
        if (i >> 2) & 1 == (i >> 1) & 1 {
            1.0
        } else {
            -1.0
        }
    });
    let dv = std::f32::consts::FRAC_1_SQRT_2;
    for o_z in [0.5f32, 0.125, 0.9] {
        let x = crossings(&corners, [0.0, 0.0, o_z], [dv, dv, 0.0], 2f32.sqrt(), 0.0);
        assert_eq!(x.n, 0, "tangent touch: {x:?}");
        assert!(
            oracle_crossings(&corners, [0.0, 0.0, o_z], [dv, dv, 0.0], 2f32.sqrt(), 0.0).is_empty()
        );
    }
    // The same polynomial given directly: f = s² − s + 0.25 = (s − ½)².
    let c = alphasurf::math::cubic::CellCubic {
        c1: -1.0,
        c2: 1.0,
        c3: 0.0,
    };
    // f = s² − s + 0.25 = (s − 0.5)²: f(0) = f(1) = 0.25.
    let x = solve_crossings(c, [0.25, 0.25], 1.0, 0.0);
    assert_eq!(x.n, 0, "exact double root: {x:?}");
    // Just above tangency: still no hit; just below: two crossings at 0.5 ± 0.01.
    let x = solve_crossings(c, [0.2501, 0.2501], 1.0, 0.0);
    assert_eq!(x.n, 0);
    let x = solve_crossings(c, [0.2499, 0.2499], 1.0, 0.0);
    assert_eq!(x.n, 2, "{x:?}");
    assert!(!x.rising[0] && x.rising[1]);
    assert!(
        (x.s[0] - 0.49).abs() < 1e-5 && (x.s[1] - 0.51).abs() < 1e-5,
        "{x:?}"
    );
    // Oracle semantics agree.
    assert!(oracle_solve(&[0.25, -1.0, 1.0, 0.0], 1.0).is_empty());
    // Merge rule (f64 oracle, where a sub-1e-6 tangent pair is representable): two crossings
    // closer than the merge distance cancel; farther apart they stay.
    let h = 0.2 * CUBIC_MERGE_EPS as f64; // half distance between the roots
    assert!(oracle_solve(&[0.25 - h * h, -1.0, 1.0, 0.0], 1.0).is_empty());
    let h = 5.0 * CUBIC_MERGE_EPS as f64;
    assert_eq!(oracle_solve(&[0.25 - h * h, -1.0, 1.0, 0.0], 1.0).len(), 2);
}

#[test]
fn no_nan_or_inf_for_any_finite_input() {
    let mut rng = Pcg64::seed_from_u64(9);
    let mut any = 0;
    for i in 0..200_000 {
        let mag = |r: &mut Pcg64| -> f32 {
            let e: f32 = r.random_range(-38.0..38.0);
            let v = 10f32.powf(e);
            if r.random() {
                v
            } else {
                -v
            }
        };
        let corners: [f32; 8] = std::array::from_fn(|_| {
            if i % 2 == 0 {
                mag(&mut rng)
            } else {
                rng.random_range(-1.0..1.0)
            }
        });
        let o = [0, 1, 2].map(|_| rng.random_range(0.0..1.0f32));
        let d = [0, 1, 2].map(|_| {
            if i % 7 == 0 {
                mag(&mut rng)
            } else {
                rng.random_range(-1.0..1.0f32)
            }
        });
        let l = if i % 5 == 0 {
            mag(&mut rng).abs()
        } else {
            rng.random_range(0.0..2.0f32)
        };
        let tau = if i % 3 == 0 {
            mag(&mut rng)
        } else {
            rng.random_range(-1.0..1.0f32)
        };
        let x = crossings(&corners, o, d, l, tau);
        assert!(x.n <= 3);
        for (s, _) in x.iter() {
            assert!(
                s.is_finite() && s >= 0.0 && s < l,
                "s={s} l={l} {corners:?} {o:?} {d:?} {tau}"
            );
            any += 1;
        }
    }
    assert!(any > 1000);
}

#[test]
fn f32_twin_meets_targets_against_oracle_on_every_class() {
    for class in CaseClass::ALL {
        let cases = gen_cases(class, 4000, 21);
        let mut missed = 0;
        let mut spurious = 0;
        let mut max_ds: f64 = 0.0;
        let mut significant = 0;
        for c in &cases {
            let oc = OracleCase::new(c);
            let got: Vec<(f64, bool)> = c.solve().iter().map(|(s, r)| (s as f64, r)).collect();
            let sc = score_case(&oc, &got, false);
            missed += sc.missed;
            spurious += sc.spurious;
            significant += sc.significant;
            max_ds = max_ds.max(sc.max_ds);
        }
        assert_eq!(missed, 0, "{}: missed (floor {FLOOR})", class.name());
        assert_eq!(spurious, 0, "{}: spurious", class.name());
        assert!(max_ds <= DS_TARGET, "{}: max |Δs| {max_ds}", class.name());
        if class != CaseClass::Triple {
            assert!(
                significant > 500,
                "{}: only {significant} significant crossings",
                class.name()
            );
        }
    }
}

#[test]
fn gpu_matches_cpu_twin() {
    let gpu = alphasurf::gpu::test_gpu();
    let row = alphasurf::check::cubic_solve::check(gpu, 7).expect("cubic_solve check runs");
    assert!(row.pass, "{row:?}");
    let msgs = gpu.validation_messages();
    assert!(msgs.is_empty(), "validation messages: {msgs:?}");
}
