//! The paper's baseline solver, for the stress suite: double-precision Vieta/trigonometric roots
//! with absolute 1e-10 thresholds for the degenerate cases (supplement eqs. 23–33, with eq. 33 read
//! as t = (A + B) − a/3), followed by the released code's acceptance, mapped to crossings by the
//! sign of f′ at each root so that it is scored exactly like our solver.
//!
//! Pipeline, as in the paper's CUDA renderer: corners widened to f64, coefficients f0..f3 by the
//! lerp form of §3.2 in f64 (no shift), then f0 − τ formed after the fact.
//! Degenerate cases (our reading of "absolute 1e-10 thresholds"): |f3| < 1e-10 → quadratic;
//! then |f2| < 1e-10 → linear; then |f1| < 1e-10 → no root; a negative quadratic discriminant → no
//! root. Acceptance (released render kernel): a root is kept when st > 0 and the hit point lies in
//! the closed voxel box, i.e. s ∈ (0, L]; identical roots are kept once (supplement: "if the roots
//! are identical, we remove the redundant ones"). No clamping of the acos argument, as in eq. 27.

/// Absolute threshold for the degenerate cases.
pub const VIETA_EPS: f64 = 1e-10;

/// A baseline crossing: the root and whether f′ > 0 there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VietaCrossing {
    pub s: f64,
    pub rising: bool,
}

/// Baseline output for one case: accepted crossings sorted by s, and how many raw roots were
/// NaN or infinite before acceptance.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct VietaResult {
    pub crossings: Vec<VietaCrossing>,
    pub non_finite: usize,
}

fn lerp(a: f64, b: f64, t: f64) -> f64 {
    a + t * (b - a)
}

/// f0..f3 of δ along the ray (paper's formulation in f64, τ not yet subtracted).
pub fn paper_coefs(corners: &[f32; 8], o: [f32; 3], d: [f32; 3]) -> [f64; 4] {
    let c: Vec<f64> = corners.iter().map(|&v| v as f64).collect();
    let (ox, oy, oz) = (o[0] as f64, o[1] as f64, o[2] as f64);
    let (dx, dy, dz) = (d[0] as f64, d[1] as f64, d[2] as f64);
    let m00 = lerp(c[0], c[1], oz);
    let m01 = lerp(c[2], c[3], oz);
    let m10 = lerp(c[4], c[5], oz);
    let m11 = lerp(c[6], c[7], oz);
    let (e00, e01, e10, e11) = (c[1] - c[0], c[3] - c[2], c[5] - c[4], c[7] - c[6]);
    let n0 = lerp(m00, m01, oy);
    let n1 = lerp(m10, m11, oy);
    let k0 = dy * (m01 - m00) + dz * lerp(e00, e01, oy);
    let k1 = dy * (m11 - m10) + dz * lerp(e10, e11, oy);
    let h0 = dy * dz * (e01 - e00);
    let h1 = dy * dz * (e11 - e10);
    [
        lerp(n0, n1, ox),
        dx * (n1 - n0) + lerp(k0, k1, ox),
        dx * (k1 - k0) + lerp(h0, h1, ox),
        dx * (h1 - h0),
    ]
}

/// Real roots of f3 t³ + f2 t² + f1 t + f0 = 0 by eqs. 23–33 (unsorted, possibly NaN).
pub fn vieta_roots(f0: f64, f1: f64, f2: f64, f3: f64) -> Vec<f64> {
    if f3.abs() < VIETA_EPS {
        if f2.abs() < VIETA_EPS {
            if f1.abs() < VIETA_EPS {
                return Vec::new();
            }
            return vec![-f0 / f1];
        }
        let disc = f1 * f1 - 4.0 * f2 * f0;
        if disc < 0.0 {
            return Vec::new();
        }
        let sq = disc.sqrt();
        return vec![(-f1 + sq) / (2.0 * f2), (-f1 - sq) / (2.0 * f2)];
    }
    let (a, b, c) = (f2 / f3, f1 / f3, f0 / f3); // eq. 24
    let q = (a * a - 3.0 * b) / 9.0; // eq. 25
    let r = (2.0 * a * a * a - 9.0 * a * b + 27.0 * c) / 54.0; // eq. 26
    let third = a / 3.0;
    if r * r < q * q * q {
        let theta = (r / (q * q * q).sqrt()).acos(); // eq. 27
        let sq = q.sqrt();
        let tau = 2.0 * std::f64::consts::PI;
        vec![
            -2.0 * sq * (theta / 3.0).cos() - third,         // eq. 28
            -2.0 * sq * ((theta - tau) / 3.0).cos() - third, // eq. 29
            -2.0 * sq * ((theta + tau) / 3.0).cos() - third, // eq. 30
        ]
    } else {
        let big_a = -r.signum() * (r.abs() + (r * r - q * q * q).sqrt()).cbrt(); // eq. 31
        let big_b = if big_a != 0.0 { q / big_a } else { 0.0 }; // eq. 32
        vec![(big_a + big_b) - third] // eq. 33 (corrected)
    }
}

/// The baseline on one case.
pub fn vieta_crossings(
    corners: &[f32; 8],
    o: [f32; 3],
    d: [f32; 3],
    l: f32,
    tau: f32,
) -> VietaResult {
    let f = paper_coefs(corners, o, d);
    let f0 = f[0] - tau as f64;
    let roots = vieta_roots(f0, f[1], f[2], f[3]);
    let non_finite = roots.iter().filter(|r| !r.is_finite()).count();
    let l = l as f64;
    let mut acc: Vec<f64> = roots.into_iter().filter(|&s| s > 0.0 && s <= l).collect();
    acc.sort_by(f64::total_cmp);
    acc.dedup();
    let crossings = acc
        .into_iter()
        .map(|s| VietaCrossing {
            s,
            rising: (3.0 * f[3] * s + 2.0 * f[2]) * s + f[1] > 0.0,
        })
        .collect();
    VietaResult {
        crossings,
        non_finite,
    }
}
