//! f64 oracle for the cell cubic: the same crossing semantics as `math::cubic` (method.md §5),
//! computed in double precision from the f32 inputs, with bisection to ~1e-15 voxel.
//!
//! The coefficients come from an independent derivation: the trilinear weights of each corner are
//! products of three linear polynomials in s (X_a(s)·Y_b(s)·Z_c(s), X_1 = o_x + s·d_x,
//! X_0 = 1 − X_1), expanded and summed with weights δ_i − τ. `tests/kernels/cubic.rs` cross-checks the
//! crossings against a dense sign scan with bisection.

/// One crossing of the oracle, with |f′(s)| for the near-tangent floor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OracleCrossing {
    pub s: f64,
    pub rising: bool,
    pub slope: f64,
}

/// Coefficients [C0 − τ, C1, C2, C3] of f(s) = δ(o′ + s·d) − τ in f64.
pub fn oracle_coefs(corners: &[f32; 8], o: [f32; 3], d: [f32; 3], tau: f32) -> [f64; 4] {
    let lin = |k: usize, bit: usize| -> [f64; 2] {
        let (ok, dk) = (o[k] as f64, d[k] as f64);
        if bit == 1 {
            [ok, dk]
        } else {
            [1.0 - ok, -dk]
        }
    };
    let mut c = [0.0f64; 4];
    for (i, &v) in corners.iter().enumerate() {
        let (a, b, cz) = ((i >> 2) & 1, (i >> 1) & 1, i & 1);
        let (x, y, z) = (lin(0, a), lin(1, b), lin(2, cz));
        // (x0 + x1 s)(y0 + y1 s)(z0 + z1 s)
        let xy = [x[0] * y[0], x[0] * y[1] + x[1] * y[0], x[1] * y[1]];
        let p = [
            xy[0] * z[0],
            xy[0] * z[1] + xy[1] * z[0],
            xy[1] * z[1] + xy[2] * z[0],
            xy[2] * z[1],
        ];
        let w = v as f64 - tau as f64;
        for k in 0..4 {
            c[k] += w * p[k];
        }
    }
    c
}

/// f(s) in f64 (Horner).
pub fn eval64(c: &[f64; 4], s: f64) -> f64 {
    ((c[3] * s + c[2]) * s + c[1]) * s + c[0]
}

/// f′(s) in f64.
pub fn deriv64(c: &[f64; 4], s: f64) -> f64 {
    (3.0 * c[3] * s + 2.0 * c[2]) * s + c[1]
}

/// Bisection in (lo, hi) with f(lo), f(hi) of strictly opposite signs, to ~1e-15.
fn bisect(c: &[f64; 4], mut lo: f64, mut hi: f64, flo: f64) -> f64 {
    let neg_lo = flo < 0.0;
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi || hi - lo < 1e-15 {
            break;
        }
        let fm = eval64(c, mid);
        if fm == 0.0 {
            return mid;
        }
        if (fm < 0.0) == neg_lo {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Crossings of the cubic `c` on [0, l) with the semantics of `math::cubic::solve_crossings`.
pub fn oracle_solve(c: &[f64; 4], l: f64) -> Vec<OracleCrossing> {
    if l.is_nan() || l <= 0.0 || c.iter().all(|&x| x == 0.0) {
        return Vec::new();
    }
    // Critical points of f: roots of A s² + 2B s + C (stable quadratic formula).
    let (a, b, cq) = (3.0 * c[3], c[2], c[1]);
    let mut bounds = vec![0.0];
    let disc = b * b - a * cq;
    if disc > 0.0 {
        let q = -(b + disc.sqrt().copysign(b));
        let mut r = vec![cq / q];
        if a != 0.0 {
            r.push(q / a);
        }
        r.retain(|&x| x > 0.0 && x < l);
        r.sort_by(f64::total_cmp);
        bounds.extend(r);
    }
    bounds.push(l);
    let vals: Vec<f64> = bounds.iter().map(|&s| eval64(c, s)).collect();
    let sign = |v: f64| if v > 0.0 { 1.0 } else { -1.0 };
    let mut raw: Vec<(f64, bool)> = Vec::new();
    let mut ps = if vals[0] == 0.0 { 0.0 } else { sign(vals[0]) };
    let mut pending = vals[0] == 0.0;
    let mut zpos = 0.0;
    for j in 0..bounds.len() - 1 {
        let v1 = vals[j + 1];
        if v1 == 0.0 {
            if !pending {
                pending = true;
                zpos = bounds[j + 1];
            }
            continue;
        }
        if pending {
            if sign(v1) != ps {
                raw.push((zpos, v1 > 0.0));
            }
            pending = false;
        } else if sign(v1) != ps {
            raw.push((bisect(c, bounds[j], bounds[j + 1], vals[j]), v1 > 0.0));
        }
        ps = sign(v1);
    }
    // Cluster merge, as in the f32 solver.
    let eps = crate::math::cubic::CUBIC_MERGE_EPS as f64 * l.max(1.0);
    let mut out = Vec::new();
    let mut i = 0;
    while i < raw.len() {
        let mut j = i + 1;
        while j < raw.len() && raw[j].0 - raw[j - 1].0 < eps {
            j += 1;
        }
        if (j - i) % 2 == 1 {
            out.push(OracleCrossing {
                s: raw[i].0,
                rising: raw[i].1,
                slope: deriv64(c, raw[i].0).abs(),
            });
        }
        i = j;
    }
    out
}

/// Oracle crossings of one case given as f32 inputs.
pub fn oracle_crossings(
    corners: &[f32; 8],
    o: [f32; 3],
    d: [f32; 3],
    l: f32,
    tau: f32,
) -> Vec<OracleCrossing> {
    oracle_solve(&oracle_coefs(corners, o, d, tau), l as f64)
}
