//! Twin of `background_spheres_step.comp`: one RMSProp step of a background's sphere texels.

use crate::abi::train::BackgroundStep;
use crate::cpu::tv::tv;
use crate::math::background_msi::SphereTable;
use crate::math::background_msi::TEXEL;
use crate::math::rmsprop::rmsprop_one;

/// The spheres' part of a background step as `record_background_step` records it: their TV
/// ([`sphere_tv`], when `s.sphere_tv` > 0), then [`background_spheres_step`] at `s`'s rates.
pub fn step_spheres(t: &mut SphereTable, grad: &mut [f32], s: &BackgroundStep) {
    if s.sphere_tv > 0.0 {
        sphere_tv(t, grad, s.sphere_tv);
    }
    let [lr_sigma, lr_colour] = s.sphere_rates();
    background_spheres_step(t, grad, lr_sigma, lr_colour, s.beta, s.eps);
}

/// Twin of `background_spheres_step.comp`: the RMSProp update of `rmsprop_one` for every texel
/// value with a nonzero gradient (σ at `lr_sigma`, the colour at `lr_colour`; values no ray
/// reached keep their running average, as svox2's sparse step), the gradient cleared.
pub fn background_spheres_step(
    s: &mut SphereTable,
    grad: &mut [f32],
    lr_sigma: f32,
    lr_colour: f32,
    beta: f32,
    eps: f32,
) {
    for (i, ((v, g), r)) in s
        .table
        .iter_mut()
        .zip(grad.iter_mut())
        .zip(&mut s.avg)
        .enumerate()
    {
        if *g != 0.0 {
            let lr = if i % TEXEL == 0 { lr_sigma } else { lr_colour };
            rmsprop_one(v, g, r, lr, beta, eps);
        }
    }
}

/// Twin of `gpu::record_sphere_tv`: the gradient of the spheres' TV of weight `lambda` added to
/// `grad` (`tv` on the table with [`BackgroundSpheres::tv_chunk`]'s chunk).
///
/// [`BackgroundSpheres::tv_chunk`]: crate::abi::buffers::BackgroundSpheres::tv_chunk
pub fn sphere_tv(t: &SphereTable, grad: &mut [f32], lambda: f32) {
    let chunk = t.shape.tv_chunk(lambda);
    tv(&t.shape.tv_links(), &t.table, grad, &mut [], &chunk);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::abi::buffers::BackgroundSpheres;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    /// The spheres' TV against f64 central differences of an independent definition on the
    /// table's (sphere, row, column) indices: forward differences to the next sphere, row and
    /// column, none past the last; loss = λ/texels · Σ √(Σ d² + 1e-9) per texel and channel.
    #[test]
    fn sphere_tv_matches_f64_central_differences_on_the_table_layout() {
        let (layers, n) = (3usize, 4usize);
        let shape = BackgroundSpheres::spanning([0.0; 3], 1.0, 10.0, layers as u32, n as u32);
        let mut rng = Pcg64::seed_from_u64(9);
        let table: Vec<f32> = (0..shape.table_len())
            .map(|_| rng.random_range(-1f32..1.0))
            .collect();
        let t = SphereTable {
            shape,
            avg: vec![0.0; table.len()],
            table,
        };
        let lambda = 0.3;
        let mut grad = vec![0f32; t.table.len()];
        sphere_tv(&t, &mut grad, lambda);
        let at = |l: usize, j: usize, i: usize, ch: usize| ((l * n + j) * n + i) * TEXEL + ch;
        let loss = |v: &[f64]| -> f64 {
            let mut total = 0.0;
            for l in 0..layers {
                for j in 0..n {
                    for i in 0..n {
                        for ch in 0..TEXEL {
                            let v0 = v[at(l, j, i, ch)];
                            let mut sq = 1e-9;
                            for (ok, k) in [
                                (l + 1 < layers, (l + 1, j, i)),
                                (j + 1 < n, (l, j + 1, i)),
                                (i + 1 < n, (l, j, i + 1)),
                            ] {
                                if ok {
                                    sq += (v[at(k.0, k.1, k.2, ch)] - v0).powi(2);
                                }
                            }
                            total += sq.sqrt();
                        }
                    }
                }
            }
            total * lambda as f64 / (layers * n * n) as f64
        };
        let base: Vec<f64> = t.table.iter().map(|&x| x as f64).collect();
        let h = 1e-6;
        let (mut num, mut den) = (0f64, 0f64);
        for k in 0..base.len() {
            let (mut p, mut m) = (base.clone(), base.clone());
            p[k] += h;
            m[k] -= h;
            let fd = (loss(&p) - loss(&m)) / (2.0 * h);
            num += (grad[k] as f64 - fd).powi(2);
            den += fd * fd;
        }
        let rel = (num / den).sqrt();
        assert!(den > 0.0 && rel < 1e-4, "sphere TV relative L2 {rel:.3e}");
    }

    /// A background step with the spheres' TV moves a texel no ray reached towards its
    /// neighbours; without it the texel stays.
    #[test]
    fn the_tv_reaches_texels_without_a_ray_gradient() {
        let shape = BackgroundSpheres {
            learn: 1,
            ..BackgroundSpheres::spanning([0.0; 3], 1.0, 10.0, 2, 4)
        };
        let mut table = vec![0.5f32; shape.table_len()];
        table[5 * TEXEL + 1] = 0.9;
        let fresh = SphereTable {
            shape,
            avg: vec![0.0; table.len()],
            table,
        };
        let step = |sphere_tv: f32| {
            let mut t = fresh.clone();
            let mut grad = vec![0f32; t.table.len()];
            let s = BackgroundStep {
                lr: 0.01,
                lr_sigma: 30.0,
                sphere_tv,
                beta: 0.95,
                eps: 1e-8,
            };
            step_spheres(&mut t, &mut grad, &s);
            assert!(grad.iter().all(|&g| g == 0.0));
            t.table
        };
        assert_eq!(step(0.0), fresh.table);
        let smoothed = step(1e-3);
        assert!(smoothed[5 * TEXEL + 1] < 0.9, "{}", smoothed[5 * TEXEL + 1]);
        assert!(smoothed[4 * TEXEL + 1] > 0.5 && smoothed[6 * TEXEL + 1] > 0.5);
        assert_eq!(smoothed[5 * TEXEL], 0.5, "σ equal to its neighbours stays");
    }
}
