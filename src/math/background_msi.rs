//! Twin of `glsl/lib/background_msi.glsl`: the background of a 360° capture, concentric spheres
//! around the grid box ([`BackgroundSpheres`]). A ray that leaves the grid meets every sphere it
//! leaves, nearest first: the point where it leaves sphere l, seen from the centre, indexes the
//! sphere's octahedral map (bilinear, its border folded as the octahedron's edges meet), whose
//! texel (σ, r, g, b) gives α_l = 1 − exp(−max(σ, 0)) and c_l = max(rgb, 0). The background
//! colour is B = Σ_l T_l α_l c_l + T_L · rgb (T_0 = 1, T_{l+1} = T_l (1 − α_l)), composited
//! behind the grid's C: C + T_grid · B. Only divisions and one square root per sphere (no
//! trigonometry), so the kernel and this twin agree to a few ulps.

use crate::abi::buffers::BackgroundSpheres;
use crate::abi::regularisers::TvChunk;
use crate::math::atomic;
use std::sync::atomic::AtomicU32;

/// Values per texel: σ, then the colour (r, g, b) before its clamp at 0.
pub const TEXEL: usize = 4;

/// Spheres of a background.
pub const SPHERE_LAYERS: u32 = 16;
/// Texels a side of each sphere's map, whatever the grid's resolution: larger maps get fewer
/// rays per texel and fit the training views' backgrounds at the expense of the test views'
/// (`capture_birdcage` at 128³: 32 texels test PSNR 29.3 dB, 64: 28.1, 128: 24.8;
/// docs/results.md).
pub const SPHERE_TEXELS: u32 = 32;
/// σ of every texel at the start (svox2's `init_sigma_bg`): each sphere lets 90 % through.
pub const SPHERE_INIT_SIGMA: f32 = 0.1;
/// The outermost sphere's radius over the farthest training camera's distance from the centre.
pub const SPHERE_FAR_OVER_CAMERAS: f32 = 4.0;

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

impl BackgroundSpheres {
    /// `layers` spheres of `size`² texels around `centre`, from radius `r0` to `far`, evenly
    /// spaced in inverse distance (one sphere: at `r0`).
    pub fn spanning(centre: [f32; 3], r0: f32, far: f32, layers: u32, size: u32) -> Self {
        let inv_step = if layers > 1 {
            (1.0 / r0 - 1.0 / far) / (layers - 1) as f32
        } else {
            0.0
        };
        BackgroundSpheres {
            centre,
            layers,
            size,
            inv_r0: 1.0 / r0,
            inv_step,
            ..Default::default()
        }
    }

    /// Radius of sphere `l`.
    pub fn radius(&self, l: u32) -> f32 {
        1.0 / (self.inv_r0 - l as f32 * self.inv_step)
    }

    /// Floats in the texel table (and in its gradient).
    pub fn table_len(&self) -> usize {
        self.layers as usize * self.size as usize * self.size as usize * TEXEL
    }

    /// The spheres' TV as `tv` computes it on a grid: the table read as a (layer, row, column)
    /// grid of [`TEXEL`] channels whose slot s holds texel s (identity links), every texel in
    /// the chunk, loss = λ/texels · Σ TV. Neighbours are the next sphere and the next texel of
    /// the map (none past a map's border); no touched flags (the spheres' step visits every
    /// value with a gradient).
    pub fn tv_chunk(&self, lambda: f32) -> TvChunk {
        let texels = self.layers * self.size * self.size;
        TvChunk {
            res: [self.layers, self.size, self.size],
            start: 0,
            count: texels,
            channels: TEXEL as u32,
            scale: lambda / texels.max(1) as f32,
            touch: 0,
        }
    }

    /// The links the spheres' TV reads: slot s holds texel s.
    pub fn tv_links(&self) -> Vec<i32> {
        (0..(self.layers * self.size * self.size) as i32).collect()
    }
}

/// Where the ray from `oc` (its origin minus the centre) along unit `d` leaves the sphere of
/// radius `r`, as the vector from the centre: `h + √(r² − |h|²)·d` with `h` the point of the line
/// nearest the centre (no cancellation when the origin is far). `None` where the line misses or
/// touches the sphere, or leaves it behind the origin.
pub fn exit_point(oc: [f32; 3], d: [f32; 3], r: f32) -> Option<[f32; 3]> {
    let b = dot(oc, d);
    let h: [f32; 3] = std::array::from_fn(|i| oc[i] - b * d[i]);
    let disc = r * r - dot(h, h);
    if !(disc > 0.0) {
        return None;
    }
    let s = disc.sqrt();
    if !(s > b) {
        return None;
    }
    Some(std::array::from_fn(|i| h[i] + s * d[i]))
}

/// Texel coordinates in [−½, size − ½]² of the direction `p` (nonzero, any length) in the
/// octahedral map: p/|p|₁ projected on z = 0, the lower half folded over the diagonals.
pub fn octahedral_uv(p: [f32; 3], size: u32) -> [f32; 2] {
    let s = p[0].abs() + p[1].abs() + p[2].abs();
    let (mut a, mut b) = (p[0] / s, p[1] / s);
    if p[2] < 0.0 {
        let (fa, fb) = (1.0 - b.abs(), 1.0 - a.abs());
        a = if p[0] >= 0.0 { fa } else { -fa };
        b = if p[1] >= 0.0 { fb } else { -fb };
    }
    let n = size as f32;
    [(a + 1.0) * 0.5 * n - 0.5, (b + 1.0) * 0.5 * n - 0.5]
}

/// One axis of [`fold`]: a coordinate `a` one past the border (−1 or n) comes back to the
/// border, and the other coordinate `b` mirrors about the map's middle.
fn fold_axis(a: i32, b: i32, n: i32) -> (i32, i32) {
    if a < 0 || a >= n {
        (a.clamp(0, n - 1), n - 1 - b)
    } else {
        (a, b)
    }
}

/// The texel (column `i`, row `j`) a bilinear tap one texel past the map's border reads: the
/// octahedron's edges are the border's halves mirrored about their midpoints.
fn fold(i: i32, j: i32, n: i32) -> u32 {
    let (i, j) = fold_axis(i, j, n);
    let (j, i) = fold_axis(j, i, n);
    (j * n + i) as u32
}

/// The four texels (index within a sphere's map) and bilinear weights at `uv`.
pub fn taps(uv: [f32; 2], size: u32) -> [(u32, f32); 4] {
    let n = size as f32;
    let u = uv[0].clamp(-0.5, n - 0.5);
    let v = uv[1].clamp(-0.5, n - 0.5);
    let (x0, y0) = (u.floor(), v.floor());
    let (fx, fy) = (u - x0, v - y0);
    let (i, j, n) = (x0 as i32, y0 as i32, size as i32);
    [
        (fold(i, j, n), (1.0 - fx) * (1.0 - fy)),
        (fold(i + 1, j, n), fx * (1.0 - fy)),
        (fold(i, j + 1, n), (1.0 - fx) * fy),
        (fold(i + 1, j + 1, n), fx * fy),
    ]
}

/// One sphere as a ray meets it: its taps (texel indices into the table, the first value of
/// each texel) and the interpolated (σ, r, g, b).
struct Layer {
    taps: [(usize, f32); 4],
    value: [f32; TEXEL],
}

fn layer(s: &BackgroundSpheres, table: &[f32], l: u32, oc: [f32; 3], d: [f32; 3]) -> Option<Layer> {
    let p = exit_point(oc, d, s.radius(l))?;
    let base = l as usize * (s.size * s.size) as usize;
    let t = taps(octahedral_uv(p, s.size), s.size);
    let taps = t.map(|(i, w)| ((base + i as usize) * TEXEL, w));
    let mut value = [0f32; TEXEL];
    for (at, w) in taps {
        for k in 0..TEXEL {
            value[k] += w * table[at + k];
        }
    }
    Some(Layer { taps, value })
}

/// α and the clamped colour of an interpolated texel.
fn shade(v: &[f32; TEXEL]) -> (f32, [f32; 3]) {
    (
        1.0 - (-v[0].max(0.0)).exp(),
        [v[1].max(0.0), v[2].max(0.0), v[3].max(0.0)],
    )
}

fn offset(s: &BackgroundSpheres, o: [f32; 3]) -> [f32; 3] {
    std::array::from_fn(|i| o[i] - s.centre[i])
}

/// The background colour B of the ray from `o` along unit `d` (scaled units) in front of `rgb`,
/// and the transmittance T_L that weights `rgb`.
pub fn composite(
    s: &BackgroundSpheres,
    table: &[f32],
    o: [f32; 3],
    d: [f32; 3],
    rgb: [f32; 3],
) -> ([f32; 3], f32) {
    march(s, table, o, d, rgb, None)
}

/// What [`backward`] adds to: the gradient, the ray's B, and dL/dB.
struct Backward<'a> {
    grad: &'a [AtomicU32],
    total: [f32; 3],
    g: [f32; 3],
}

/// The spheres the ray leaves, nearest first: B and T_L as [`composite`] returns them, and with
/// `back` the texel gradient added as [`backward`] says (one loop for both, as the kernel's).
fn march(
    s: &BackgroundSpheres,
    table: &[f32],
    o: [f32; 3],
    d: [f32; 3],
    rgb: [f32; 3],
    back: Option<Backward>,
) -> ([f32; 3], f32) {
    let oc = offset(s, o);
    let mut color = [0f32; 3];
    let mut t = 1f32;
    for l in 0..s.layers {
        let Some(ly) = layer(s, table, l, oc, d) else {
            continue;
        };
        let (alpha, c) = shade(&ly.value);
        let wt = t * alpha;
        for ch in 0..3 {
            color[ch] += wt * c[ch];
        }
        let tn = t * (1.0 - alpha);
        if let Some(b) = &back {
            let mut dv = [0f32; TEXEL];
            if ly.value[0] > 0.0 {
                dv[0] = (0..3)
                    .map(|ch| b.g[ch] * (tn * c[ch] - (b.total[ch] - color[ch])))
                    .sum();
            }
            for ch in 0..3 {
                if ly.value[1 + ch] > 0.0 {
                    dv[1 + ch] = b.g[ch] * wt;
                }
            }
            for (at, w) in ly.taps {
                for k in 0..TEXEL {
                    if dv[k] != 0.0 {
                        atomic::add(&b.grad[at + k], w * dv[k]);
                    }
                }
            }
        }
        t = tn;
    }
    (std::array::from_fn(|ch| color[ch] + t * rgb[ch]), t)
}

/// What a ray meets behind the grid, as the twins read it: the colour, and the spheres with their
/// texel values when the run has them.
#[derive(Clone, Copy, Debug)]
pub struct BackgroundView<'a> {
    pub rgb: [f32; 3],
    pub spheres: Option<(&'a BackgroundSpheres, &'a [f32])>,
}

impl<'a> BackgroundView<'a> {
    /// The colour `rgb`, behind `spheres` when there are any.
    pub fn new(rgb: [f32; 3], spheres: Option<&'a SphereTable>) -> Self {
        BackgroundView {
            rgb,
            spheres: spheres.map(|s| (&s.shape, &s.table[..])),
        }
    }

    /// The background B of the ray from `o` along unit `d` and the weight T_L of the colour in
    /// it (`rgb` and 1 without spheres, bit for bit).
    pub fn behind(&self, o: [f32; 3], d: [f32; 3]) -> ([f32; 3], f32) {
        match self.spheres {
            Some((s, table)) => composite(s, table, o, d, self.rgb),
            None => (self.rgb, 1.0),
        }
    }
}

/// Adds dL/d(texel values) of the ray from `o` along `d` to `grad` (float atomics, as the
/// kernels), given dL/dB = `g` and the ray's `total` = B from [`composite`]: per sphere
/// dL/dσ = Σ_ch g·(T_{l+1} c_l − (B − B_≤l)) where σ > 0, dL/dc_l = g·T_l α_l where the colour
/// is positive, spread over the four taps by their weights.
pub fn backward(
    s: &BackgroundSpheres,
    table: &[f32],
    grad: &[AtomicU32],
    o: [f32; 3],
    d: [f32; 3],
    total: [f32; 3],
    g: [f32; 3],
) {
    march(s, table, o, d, [0.0; 3], Some(Backward { grad, total, g }));
}

/// A background's spheres on the host: their shape, texel values (σ, r, g, b per texel) and the
/// values' RMSProp running averages.
#[derive(Clone, Debug, PartialEq)]
pub struct SphereTable {
    pub shape: BackgroundSpheres,
    pub table: Vec<f32>,
    pub avg: Vec<f32>,
}

impl SphereTable {
    /// Spheres around the grid box `centre ± radius` (scaled units): the first one around the
    /// box's corners, the last [`SPHERE_FAR_OVER_CAMERAS`] times as far as the farthest camera
    /// (`cameras`: their centres); maps of [`SPHERE_TEXELS`] a side; every texel
    /// σ = [`SPHERE_INIT_SIGMA`] and colour `rgb`; learned.
    pub fn around(centre: [f32; 3], radius: f32, cameras: &[[f32; 3]], rgb: [f32; 3]) -> Self {
        let r0 = radius * 3f32.sqrt();
        let farthest = cameras
            .iter()
            .map(|c| {
                (0..3)
                    .map(|i| (c[i] - centre[i]).powi(2))
                    .sum::<f32>()
                    .sqrt()
            })
            .fold(0f32, f32::max);
        let far = (SPHERE_FAR_OVER_CAMERAS * farthest).max(2.0 * r0);
        let shape = BackgroundSpheres {
            learn: 1,
            ..BackgroundSpheres::spanning(centre, r0, far, SPHERE_LAYERS, SPHERE_TEXELS)
        };
        let texel = [SPHERE_INIT_SIGMA, rgb[0], rgb[1], rgb[2]];
        let table: Vec<f32> = texel
            .iter()
            .copied()
            .cycle()
            .take(shape.table_len())
            .collect();
        SphereTable {
            shape,
            avg: vec![0.0; table.len()],
            table,
        }
    }

    /// Whether the training passes accumulate their gradient.
    pub fn learned(&self) -> bool {
        self.shape.learn != 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    fn spheres() -> BackgroundSpheres {
        BackgroundSpheres::spanning([0.1, -0.2, 0.05], 1.8, 20.0, 5, 6)
    }

    fn random_table(s: &BackgroundSpheres, rng: &mut Pcg64) -> Vec<f32> {
        (0..s.table_len())
            .map(|i| match i % TEXEL {
                0 => rng.random_range(-0.2f32..1.5),
                _ => rng.random_range(-0.1f32..1.0),
            })
            .collect()
    }

    fn unit(v: [f32; 3]) -> [f32; 3] {
        let n = dot(v, v).sqrt();
        v.map(|x| x / n)
    }

    /// A camera on a sphere of radius 4 looking roughly at the centre, as a capture's.
    fn camera_ray(rng: &mut Pcg64) -> ([f32; 3], [f32; 3]) {
        let o = unit(std::array::from_fn(|_| rng.random_range(-1f32..1.0))).map(|x| 4.0 * x);
        let aim: [f32; 3] = std::array::from_fn(|_| rng.random_range(-1.5f32..1.5));
        (o, unit(std::array::from_fn(|i| aim[i] - o[i])))
    }

    #[test]
    fn radii_span_from_the_inner_sphere_to_far_in_inverse_distance() {
        let s = spheres();
        assert!((s.radius(0) - 1.8).abs() < 1e-6);
        assert!((s.radius(4) - 20.0).abs() < 1e-3);
        let inv: Vec<f32> = (0..5).map(|l| 1.0 / s.radius(l)).collect();
        for w in inv.windows(3) {
            assert!(((w[0] - w[1]) - (w[1] - w[2])).abs() < 1e-6);
        }
    }

    #[test]
    fn exit_points_lie_on_the_sphere_ahead_and_grow_with_the_radius() {
        let mut rng = Pcg64::seed_from_u64(1);
        for _ in 0..1000 {
            let (o, d) = camera_ray(&mut rng);
            let mut last = 0f32;
            for r in [1.0f32, 2.0, 4.5, 9.0] {
                let Some(p) = exit_point(o, d, r) else {
                    assert!(r < 4.0 + 1e-3, "a ray from inside sphere {r} must leave it");
                    continue;
                };
                assert!((dot(p, p).sqrt() - r).abs() < 1e-5 * r);
                let t = dot(std::array::from_fn(|i| p[i] - o[i]), d);
                assert!(t > last, "exits in order along the ray");
                last = t;
            }
        }
        // Pointing away from a sphere the camera is outside of: none.
        assert!(exit_point([4.0, 0.0, 0.0], [1.0, 0.0, 0.0], 1.0).is_none());
        // Missing it, and touching it: none.
        assert!(exit_point([4.0, 2.0, 0.0], [-1.0, 0.0, 0.0], 1.0).is_none());
        assert!(exit_point([4.0, 1.0, 0.0], [-1.0, 0.0, 0.0], 1.0).is_none());
    }

    /// The map is continuous over the sphere: directions a hair apart, across the fold of the
    /// lower half and the border's mirrored edges, read the same value.
    #[test]
    fn the_octahedral_map_is_continuous_across_its_folds() {
        let s = BackgroundSpheres::spanning([0.0; 3], 1.0, 10.0, 1, 7);
        let mut rng = Pcg64::seed_from_u64(2);
        let table = random_table(&s, &mut rng);
        let read = |p: [f32; 3]| {
            let t = taps(octahedral_uv(p, s.size), s.size);
            t.iter()
                .map(|&(i, w)| w * table[i as usize * TEXEL + 1])
                .sum::<f32>()
        };
        let eps = 1e-5f32;
        for _ in 0..2000 {
            let x: f32 = rng.random_range(-1.0..1.0);
            let y: f32 = rng.random_range(-1.0..1.0);
            let z = -0.2 - 0.5 * rng.random_range(0f32..1.0);
            // Across z = 0 (the fold), and across the planes x = 0 and y = 0 below it (the
            // border's mirrored halves); |p|₁ ≥ 0.2, so the two directions' map coordinates
            // differ by ≲ 10⁻³ texels where the map is continuous.
            let xf = if x.abs() + y.abs() < 0.2 { 0.5 } else { x };
            for (a, b) in [
                ([xf, y, eps], [xf, y, -eps]),
                ([eps, y, z], [-eps, y, z]),
                ([x, eps, z], [x, -eps, z]),
            ] {
                assert!((read(a) - read(b)).abs() < 1e-3, "{a:?} {b:?}");
            }
        }
    }

    #[test]
    fn taps_stay_in_the_map_and_their_weights_sum_to_one() {
        let mut rng = Pcg64::seed_from_u64(3);
        for size in [1, 2, 5, 64] {
            for _ in 0..2000 {
                let p = [(); 3].map(|_| rng.random_range(-1f32..1.0));
                let t = taps(octahedral_uv(p, size), size);
                assert!(t.iter().all(|&(i, _)| i < size * size));
                assert!((t.iter().map(|x| x.1).sum::<f32>() - 1.0).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn an_opaque_first_sphere_hides_the_rest_and_no_sphere_leaves_the_colour() {
        let s = spheres();
        let mut table = vec![0f32; s.table_len()];
        let layer = (s.size * s.size) as usize * TEXEL;
        for t in table[..layer].chunks_exact_mut(TEXEL) {
            t.copy_from_slice(&[80.0, 0.2, 0.4, 0.6]);
        }
        for t in table[layer..].chunks_exact_mut(TEXEL) {
            t.copy_from_slice(&[1.0, 1.0, 0.0, 0.0]);
        }
        let (b, t) = composite(
            &s,
            &table,
            [0.3, 0.1, 0.0],
            unit([1.0, 2.0, -0.5]),
            [1.0; 3],
        );
        assert!(t < 1e-30);
        for (x, want) in b.iter().zip([0.2, 0.4, 0.6]) {
            assert!((x - want).abs() < 1e-6);
        }
        let none = BackgroundSpheres { layers: 0, ..s };
        assert_eq!(
            composite(&none, &[], [0.0; 3], [0.0, 0.0, 1.0], [0.3, 0.5, 0.7]),
            ([0.3, 0.5, 0.7], 1.0)
        );
    }

    /// The background in f64, the same formulation as [`composite`] (the taps' positions are
    /// computed in f32: they do not depend on the table).
    fn composite_f64(
        s: &BackgroundSpheres,
        table: &[f64],
        o: [f32; 3],
        d: [f32; 3],
        rgb: [f64; 3],
    ) -> [f64; 3] {
        let oc = offset(s, o);
        let (mut color, mut t) = ([0f64; 3], 1f64);
        for l in 0..s.layers {
            let Some(p) = exit_point(oc, d, s.radius(l)) else {
                continue;
            };
            let base = l as usize * (s.size * s.size) as usize;
            let mut v = [0f64; TEXEL];
            for (i, w) in taps(octahedral_uv(p, s.size), s.size) {
                for k in 0..TEXEL {
                    v[k] += w as f64 * table[(base + i as usize) * TEXEL + k];
                }
            }
            let alpha = 1.0 - (-v[0].max(0.0)).exp();
            for ch in 0..3 {
                color[ch] += t * alpha * v[1 + ch].max(0.0);
            }
            t *= 1.0 - alpha;
        }
        std::array::from_fn(|ch| color[ch] + t * rgb[ch])
    }

    /// The backward pass against f64 central differences of the loss g·B, for every texel value
    /// a ray reads (values away from the ReLU kinks by at least the step).
    #[test]
    fn the_texel_gradient_matches_f64_central_differences() {
        let s = spheres();
        let mut rng = Pcg64::seed_from_u64(4);
        let rgb = [0.3f32, 0.6, 0.9];
        let mut checked = 0;
        for _ in 0..40 {
            let mut table = random_table(&s, &mut rng);
            for v in table.iter_mut() {
                if v.abs() < 0.01 {
                    *v = 0.05;
                }
            }
            let (o, d) = camera_ray(&mut rng);
            let g: [f32; 3] = [(); 3].map(|_| rng.random_range(-1f32..1.0));
            let (total, _) = composite(&s, &table, o, d, rgb);
            let mut grad = vec![0f32; table.len()];
            backward(&s, &table, atomic::as_atomic(&mut grad), o, d, total, g);
            let t64: Vec<f64> = table.iter().map(|&x| x as f64).collect();
            let rgb64 = rgb.map(|x| x as f64);
            let loss = |t: &[f64]| {
                let b = composite_f64(&s, t, o, d, rgb64);
                (0..3).map(|ch| g[ch] as f64 * b[ch]).sum::<f64>()
            };
            let h = 1e-6;
            for i in 0..table.len() {
                let mut tp = t64.clone();
                tp[i] += h;
                let mut tm = t64.clone();
                tm[i] -= h;
                let want = (loss(&tp) - loss(&tm)) / (2.0 * h);
                let got = grad[i] as f64;
                assert!(
                    (got - want).abs() <= 1e-5 + 1e-4 * want.abs(),
                    "value {i}: analytic {got}, central difference {want}"
                );
                if want != 0.0 {
                    checked += 1;
                }
            }
        }
        assert!(checked > 500, "only {checked} nonzero derivatives checked");
    }
}
