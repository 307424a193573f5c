//! Twin of `loss_sum.comp`: the sums over rays of the leading loss fields of each record, in the
//! kernel's order (per invocation t the records t, t + T, …, then the shared-memory tree), so
//! that both give the same bits.

use crate::abi::consts::{LOSS_SUM_FIELDS, LOSS_SUM_THREADS};

/// The sums over the `n` records of `stride` floats in `src` of their first `fields` floats
/// (at most `LOSS_SUM_FIELDS`; the remaining entries are 0).
pub fn loss_sum(
    src: &[f32],
    n: usize,
    stride: usize,
    fields: usize,
) -> [f32; LOSS_SUM_FIELDS as usize] {
    const T: usize = LOSS_SUM_THREADS as usize;
    const F: usize = LOSS_SUM_FIELDS as usize;
    let fields = fields.min(F);
    let mut part = vec![[0f32; F]; T];
    for (t, acc) in part.iter_mut().enumerate() {
        let mut r = t;
        while r < n {
            for f in 0..fields {
                acc[f] += src[r * stride + f];
            }
            r += T;
        }
    }
    let mut h = T / 2;
    while h > 0 {
        for t in 0..h {
            for f in 0..F {
                part[t][f] += part[t + h][f];
            }
        }
        h /= 2;
    }
    let mut out = [0f32; F];
    out[..fields].copy_from_slice(&part[0][..fields]);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sums_each_field_and_propagates_non_finite() {
        // 1000 records of 4 floats: field f of ray r is f + 1 (exact in f32 at these sizes).
        let n = 1000;
        let src: Vec<f32> = (0..n).flat_map(|_| [1.0, 2.0, 3.0, 4.0]).collect();
        assert_eq!(loss_sum(&src, n, 4, 3), [1000.0, 2000.0, 3000.0, 0.0]);
        assert_eq!(loss_sum(&src, 0, 4, 3), [0.0; 4]);
        let mut bad = src.clone();
        bad[4 * 517 + 1] = f32::NAN;
        bad[4 * 3] = f32::INFINITY;
        let s = loss_sum(&bad, n, 4, 2);
        assert!(s[0].is_infinite() && s[1].is_nan());
    }
}
