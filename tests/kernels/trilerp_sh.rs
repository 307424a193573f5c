//! Trilinear interpolation and degree-2 SH (`math::trilerp`, `math::sh`, twins of the GLSL libs)
//! against independent f64 evaluations: gradient against central finite differences, weights,
//! SH basis values, orthonormality over the sphere; GPU parity rows.

use alphasurf::math::sh::{sh_basis, sh_rgb};
use alphasurf::math::trilerp::{trilerp, trilerp_grad, trilerp_weights};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// f64 trilerp as the weighted corner sum (a different formulation from the nested lerps).
fn trilerp64(c: &[f32; 8], p: [f64; 3]) -> f64 {
    let mut v = 0.0;
    for (i, ci) in c.iter().enumerate() {
        let f = |bit: usize, x: f64| if i >> bit & 1 == 1 { x } else { 1.0 - x };
        v += f(2, p[0]) * f(1, p[1]) * f(0, p[2]) * *ci as f64;
    }
    v
}

fn random_cell(rng: &mut Pcg64) -> ([f32; 8], [f32; 3], f64) {
    let scale = 10f32.powi(rng.random_range(-3..=3));
    let c: [f32; 8] = std::array::from_fn(|_| scale * rng.random_range(-1.0f32..1.0));
    let p: [f32; 3] = std::array::from_fn(|_| rng.random_range(0.0f32..=1.0));
    let s = c.iter().fold(0f32, |m, x| m.max(x.abs())) as f64;
    (c, p, s)
}

#[test]
fn trilerp_value_and_gradient_against_f64_finite_differences() {
    let mut rng = Pcg64::seed_from_u64(5);
    let h = 1e-3;
    let mut worst = 0f64;
    for _ in 0..20_000 {
        let (c, p, s) = random_cell(&mut rng);
        let p64 = p.map(|x| x as f64);
        let (v, g) = trilerp_grad(&c, p);
        assert_eq!(v, trilerp(&c, p), "trilerp_grad's value is trilerp's");
        let err = (v as f64 - trilerp64(&c, p64)).abs() / s;
        assert!(err < 1e-6, "value error {err} at {p:?} {c:?}");
        for a in 0..3 {
            let mut lo = p64;
            let mut hi = p64;
            lo[a] -= h;
            hi[a] += h;
            let fd = (trilerp64(&c, hi) - trilerp64(&c, lo)) / (2.0 * h);
            let err = (g[a] as f64 - fd).abs() / s;
            worst = worst.max(err);
            assert!(
                err < 1e-5,
                "axis {a}: analytic {} fd {fd} at {p:?} {c:?}",
                g[a]
            );
        }
    }
    println!("worst gradient error / max|corner|: {worst:e}");
}

#[test]
fn trilerp_weights_sum_to_one_and_reproduce_the_value() {
    let mut rng = Pcg64::seed_from_u64(6);
    for i in 0..20_000 {
        let (c, mut p, s) = random_cell(&mut rng);
        if i % 4 == 0 {
            p = std::array::from_fn(|_| [0.0, 0.5, 1.0][rng.random_range(0..3)]);
        }
        let w = trilerp_weights(p);
        let sum: f64 = w.iter().map(|x| *x as f64).sum();
        assert!((sum - 1.0).abs() < 1e-6, "weights at {p:?} sum to {sum}");
        assert!(w.iter().all(|x| (0.0..=1.0).contains(x)));
        let wc: f64 = w.iter().zip(&c).map(|(w, c)| *w as f64 * *c as f64).sum();
        let v = trilerp(&c, p) as f64;
        assert!((wc - v).abs() / s < 1e-6, "Σ w·c {wc} vs trilerp {v}");
        // Corner order 000, 001, …, 111: at a corner p the weight is one-hot and the value is
        // the corner's (up to one rounding: the FMA lerp a + 1·(b − a) need not return b exactly).
        if p.iter().all(|x| *x == 0.0 || *x == 1.0) {
            let idx = 4 * p[0] as usize + 2 * p[1] as usize + p[2] as usize;
            assert_eq!(w[idx], 1.0);
            assert!((trilerp(&c, p) - c[idx]).abs() as f64 <= 2.0 * f32::EPSILON as f64 * s);
        }
    }
}

/// f64 real SH of degree 2 from the closed forms with exact normalisation constants.
fn sh64(d: [f64; 3]) -> [f64; 9] {
    let pi = std::f64::consts::PI;
    let [x, y, z] = d;
    let c0 = 0.5 / pi.sqrt();
    let c1 = (3.0 / (4.0 * pi)).sqrt();
    let c2 = 0.5 * (15.0 / pi).sqrt();
    let c3 = 0.25 * (5.0 / pi).sqrt();
    let c4 = 0.25 * (15.0 / pi).sqrt();
    [
        c0,
        -c1 * y,
        c1 * z,
        -c1 * x,
        c2 * x * y,
        -c2 * y * z,
        c3 * (2.0 * z * z - x * x - y * y),
        -c2 * x * z,
        c4 * (x * x - y * y),
    ]
}

fn unit(rng: &mut Pcg64) -> [f32; 3] {
    loop {
        let v: [f64; 3] = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
        let l = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if l > 1e-2 && l <= 1.0 {
            return v.map(|x| (x / l) as f32);
        }
    }
}

#[test]
fn sh_basis_and_colour_against_f64() {
    let mut rng = Pcg64::seed_from_u64(7);
    for _ in 0..20_000 {
        let d = unit(&mut rng);
        let y = sh_basis(d);
        let y64 = sh64(d.map(|x| x as f64));
        for k in 0..9 {
            assert!(
                (y[k] as f64 - y64[k]).abs() < 1e-6,
                "Y{k} at {d:?}: {} vs {}",
                y[k],
                y64[k]
            );
        }
        let coefs: [f32; 27] = std::array::from_fn(|_| rng.random_range(-1.0f32..1.0));
        let rgb = sh_rgb(&y, &coefs);
        for ch in 0..3 {
            let s: f64 = (0..9).map(|k| y64[k] * coefs[9 * ch + k] as f64).sum();
            let want = (s + 0.5).max(0.0);
            assert!(
                (rgb[ch] as f64 - want).abs() < 1e-5,
                "channel {ch}: {} vs {want}",
                rgb[ch]
            );
        }
    }
    // Colour of all-zero coefficients is mid-grey; a large negative DC clamps to 0, not below.
    let y = sh_basis([0.0, 0.0, 1.0]);
    assert_eq!(sh_rgb(&y, &[0.0; 27]), [0.5; 3]);
    let mut c = [0.0; 27];
    c[9] = -10.0;
    assert_eq!(sh_rgb(&y, &c)[1], 0.0);
}

#[test]
fn sh_basis_is_orthonormal_on_the_sphere() {
    // Midpoint rule, uniform in z = cos θ and φ (area-uniform by Archimedes): ∫ = 4π·mean.
    let (nz, nphi) = (1000, 48);
    let mut gram = [[0f64; 9]; 9];
    for i in 0..nz {
        let z = -1.0 + (i as f64 + 0.5) * 2.0 / nz as f64;
        let r = (1.0 - z * z).sqrt();
        for j in 0..nphi {
            let phi = (j as f64 + 0.5) * std::f64::consts::TAU / nphi as f64;
            let d = [(r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32];
            let y = sh_basis(d);
            for a in 0..9 {
                for b in 0..9 {
                    gram[a][b] += y[a] as f64 * y[b] as f64;
                }
            }
        }
    }
    let w = 4.0 * std::f64::consts::PI / (nz * nphi) as f64;
    for (a, row) in gram.iter().enumerate() {
        for (b, g) in row.iter().enumerate() {
            let want = if a == b { 1.0 } else { 0.0 };
            assert!((g * w - want).abs() < 1e-4, "<Y{a}, Y{b}> = {}", g * w);
        }
    }
}

#[test]
fn gpu_parity() {
    let gpu = alphasurf::gpu::test_gpu();
    for row in [
        alphasurf::check::trilerp_eval::check(gpu, 3).expect("trilerp_eval check runs"),
        alphasurf::check::sh_eval::check(gpu, 4).expect("sh_eval check runs"),
    ] {
        println!("{row:?}");
        assert!(row.pass, "{row:?}");
    }
    assert!(
        gpu.validation_messages().is_empty(),
        "{:?}",
        gpu.validation_messages()
    );
}
