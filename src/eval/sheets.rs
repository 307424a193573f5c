//! Thin sheets' two faces moved onto the sheet: across a part thinner than stage 1 can resolve
//! (a zero-thickness blade, a board a cell thick) the density is a bump about four cells wide,
//! and each level set crosses it twice, one to two cells either side of the part
//! (docs/tuning.md, "the two faces of a thin sheet"). A point is on such a sheet when
//! - inward along its normal (toward increasing field) the field falls below the lowest level
//!   within [`SheetRule::reach`] cells: the part ends there, it is no solid's face;
//! - the normals of the points in the 7³ cells around its own mostly share one axis (the
//!   largest eigenvalue of Σ n nᵀ over their trace at least [`SheetRule::coherence`]): a sheet,
//!   not a wire, whose level sets are tubes with normals turning round its axis, nor a bar as
//!   wide as it is thick.
//!
//! Such a point moves inward by half the distance at which the field fell below the lowest
//! level: onto the bump's middle, where its other face's points arrive too.

use crate::abi::extract::ExtractPoint;
use crate::eval::extract::grid_position;
use crate::eval::outer_level::{unit, Field};
use crate::grid::slot_vertex;
use rayon::prelude::*;
use std::collections::HashMap;

/// What makes a point a sheet's.
#[derive(Clone, Copy, Debug)]
pub struct SheetRule {
    /// Cells inward along the normal within which the field must fall below the lowest level.
    pub reach: f32,
    /// Cells the search starts inward of the point (the point's own level set lies there).
    pub skip: f32,
    /// The normals compared are those of the points in the (2·box_radius + 1)³ cells around a
    /// point's: wide enough to take in a bar's side faces or a tube's far side, so that only a
    /// part much wider than it is thick counts as a sheet.
    pub box_radius: u32,
    /// Least share of the largest eigenvalue of Σ n nᵀ in its trace (1: parallel normals;
    /// about ½ round a tube, ⅓ where they point every way).
    pub coherence: f64,
}

impl Default for SheetRule {
    /// Measured on the four thin development scenes (docs/tuning.md).
    fn default() -> Self {
        SheetRule {
            reach: 4.0,
            skip: 0.4,
            box_radius: 3,
            coherence: 0.7,
        }
    }
}

/// Moves the points of thin sheets onto their middle (grid units, `local` may leave [0, 1]³);
/// `lowest` is the lowest extracted level. Returns how many moved.
pub fn centre_sheets(
    points: &mut [ExtractPoint],
    field: &Field,
    lowest: f32,
    rule: &SheetRule,
) -> usize {
    let normals: Vec<Option<[f32; 3]>> = points.par_iter().map(|p| unit(p.grad)).collect();
    // Where the part ends inward, for the points on a part that ends within reach.
    let exits: Vec<Option<f32>> = points
        .par_iter()
        .zip(&normals)
        .map(|(p, n)| {
            let n = (*n)?;
            field.falls_below(
                grid_position(field.res, p),
                n,
                lowest,
                rule.skip,
                rule.reach,
            )
        })
        .collect();
    let coherence = point_coherence(points, &normals, &exits, field.res, rule);
    let mut moved = 0;
    for (((p, n), exit), c) in points.iter_mut().zip(&normals).zip(&exits).zip(&coherence) {
        let (Some(n), Some(t)) = (n, exit) else {
            continue;
        };
        if *c < rule.coherence {
            continue;
        }
        for (l, ni) in p.local.iter_mut().zip(n) {
            *l += 0.5 * t * ni;
        }
        moved += 1;
    }
    moved
}

/// Σ n nᵀ of a set of unit normals: xx, yy, zz, xy, xz, yz.
type Moments = [f64; 6];

fn moments(n: [f32; 3]) -> Moments {
    let [x, y, z] = n.map(f64::from);
    [x * x, y * y, z * z, x * y, x * z, y * z]
}

/// For each point with an exit: the coherence of the normals of every point in the cells of
/// `rule`'s box around its own cell (0 for the others).
fn point_coherence(
    points: &[ExtractPoint],
    normals: &[Option<[f32; 3]>],
    exits: &[Option<f32>],
    res: [u32; 3],
    rule: &SheetRule,
) -> Vec<f64> {
    let mut sums: HashMap<u32, Moments> = HashMap::new();
    for (p, n) in points.iter().zip(normals) {
        if let Some(n) = n {
            let m = sums.entry(p.cell).or_insert([0.0; 6]);
            for (a, x) in m.iter_mut().zip(moments(*n)) {
                *a += x;
            }
        }
    }
    let mut wanted: Vec<u32> = points
        .iter()
        .zip(exits)
        .filter(|(_, e)| e.is_some())
        .map(|(p, _)| p.cell)
        .collect();
    wanted.sort_unstable();
    wanted.dedup();
    let r = rule.box_radius as i64;
    let share: HashMap<u32, f64> = wanted
        .into_par_iter()
        .map(|cell| {
            let v = slot_vertex(res, cell as usize).map(|c| c as i64);
            let mut m = [0f64; 6];
            for dx in -r..=r {
                for dy in -r..=r {
                    for dz in -r..=r {
                        let q = [v[0] + dx, v[1] + dy, v[2] + dz];
                        if (0..3).any(|i| q[i] < 0 || q[i] >= res[i] as i64) {
                            continue;
                        }
                        let slot = (q[0] * res[1] as i64 + q[1]) * res[2] as i64 + q[2];
                        if let Some(s) = sums.get(&(slot as u32)) {
                            for (a, x) in m.iter_mut().zip(s) {
                                *a += x;
                            }
                        }
                    }
                }
            }
            (cell, largest_share(&m))
        })
        .collect();
    points
        .iter()
        .zip(exits)
        .map(|(p, e)| if e.is_some() { share[&p.cell] } else { 0.0 })
        .collect()
}

/// The largest eigenvalue of the symmetric positive semi-definite matrix `m` over its trace
/// (closed form for 3×3: the eigenvalues are q + 2p·cos(φ + 2πk/3)); 0 for a zero matrix.
fn largest_share(m: &Moments) -> f64 {
    let [a, b, c, d, e, f] = *m;
    let trace = a + b + c;
    if trace <= 0.0 {
        return 0.0;
    }
    let q = trace / 3.0;
    let off = d * d + e * e + f * f;
    let p2 = (a - q).powi(2) + (b - q).powi(2) + (c - q).powi(2) + 2.0 * off;
    if p2 <= 1e-30 * trace * trace {
        return 1.0 / 3.0;
    }
    let p = (p2 / 6.0).sqrt();
    // det((M − qI)/p) / 2, the cosine of 3φ.
    let (a, b, c) = ((a - q) / p, (b - q) / p, (c - q) / p);
    let (d, e, f) = (d / p, e / p, f / p);
    let det = a * (b * c - f * f) - d * (d * c - f * e) + e * (d * f - b * e);
    let phi = (det / 2.0).clamp(-1.0, 1.0).acos() / 3.0;
    (q + 2.0 * p * phi.cos()) / trace
}

#[cfg(test)]
mod tests {
    use super::*;

    const N: u32 = 24;
    const RES: [u32; 3] = [N, N, N];

    fn slot(v: [usize; 3]) -> usize {
        (v[0] * N as usize + v[1]) * N as usize + v[2]
    }

    /// A field f(x, y, z) = profile on every vertex.
    fn field_of(profile: impl Fn([f32; 3]) -> f32) -> (Vec<i32>, Vec<f32>) {
        let n = (N * N * N) as usize;
        let links = (0..n as i32).collect();
        let values = (0..n)
            .map(|s| {
                let v = slot_vertex(RES, s);
                profile(v.map(|c| c as f32))
            })
            .collect();
        (links, values)
    }

    /// A point at grid position `g` with inward gradient `grad`.
    fn point(g: [f32; 3], grad: [f32; 3]) -> ExtractPoint {
        let c = g.map(|x| x.floor());
        ExtractPoint {
            local: std::array::from_fn(|i| g[i] - c[i]),
            grad,
            alpha: 1.0,
            cell: slot(c.map(|x| x as usize)) as u32,
            level: 0,
            ray: 0,
        }
    }

    fn position(p: &ExtractPoint) -> [f32; 3] {
        grid_position(RES, p)
    }

    /// Points on both faces of a level-`level` crossing of a bump across x = 12 (a sheet), on a
    /// patch of the y–z plane.
    fn sheet_points(half_width: f32) -> Vec<ExtractPoint> {
        let mut pts = Vec::new();
        for j in 0..12 {
            for k in 0..12 {
                let (y, z) = (6.0 + j as f32 * 0.5, 6.0 + k as f32 * 0.5);
                pts.push(point([12.0 - half_width, y, z], [1.0, 0.0, 0.0]));
                pts.push(point([12.0 + half_width, y, z], [-1.0, 0.0, 0.0]));
            }
        }
        pts
    }

    #[test]
    fn a_sheets_two_faces_meet_in_its_middle() {
        // A bump 60·exp(−(x − 12)²/2): level 10 is crossed 1.89 cells either side of x = 12.
        let (links, values) = field_of(|v| 60.0 * (-(v[0] - 12.0).powi(2) / 2.0).exp());
        let field = Field {
            res: RES,
            links: &links,
            values: &values,
        };
        let half = (2.0 * 6f32.ln()).sqrt();
        let mut pts = sheet_points(half);
        let moved = centre_sheets(&mut pts, &field, 10.0, &SheetRule::default());
        assert_eq!(moved, pts.len());
        for p in &pts {
            let x = position(p)[0];
            // The exit is found on a 0.1-cell lattice: within 0.05 of the middle, plus the
            // trilinear field's error on a curved profile.
            assert!((x - 12.0).abs() < 0.1, "x = {x}");
        }
    }

    /// On the field `profile`, `centre_sheets` (level 10) moves none of `pts`.
    fn assert_none_move(profile: impl Fn([f32; 3]) -> f32, mut pts: Vec<ExtractPoint>) {
        let (links, values) = field_of(profile);
        let field = Field {
            res: RES,
            links: &links,
            values: &values,
        };
        let before: Vec<[f32; 3]> = pts.iter().map(position).collect();
        assert_eq!(
            centre_sheets(&mut pts, &field, 10.0, &SheetRule::default()),
            0
        );
        assert_eq!(pts.iter().map(position).collect::<Vec<_>>(), before);
    }

    #[test]
    fn a_solids_face_and_a_wires_tube_stay() {
        // A solid: the field rises across x = 12 and stays high (no exit within reach).
        let face: Vec<ExtractPoint> = sheet_points(0.5)
            .into_iter()
            .filter(|p| p.grad[0] > 0.0)
            .collect();
        assert_none_move(|v| if v[0] >= 12.0 { 60.0 } else { 0.0 }, face);

        // A wire along z through (12, 12): a radial bump; its level set is a tube of radius
        // 1.5 whose normals turn round the axis (coherence about ½), so nothing moves although
        // the field falls below the level within reach.
        let mut tube = Vec::new();
        for a in 0..48 {
            let t = a as f32 * std::f32::consts::TAU / 48.0;
            let (c, s) = (t.cos(), t.sin());
            for k in 0..12 {
                let z = 6.0 + k as f32;
                tube.push(point([12.0 + 1.5 * c, 12.0 + 1.5 * s, z], [-c, -s, 0.0]));
            }
        }
        assert_none_move(
            |v| 60.0 * (-((v[0] - 12.0).powi(2) + (v[1] - 12.0).powi(2)) / 2.0).exp(),
            tube,
        );
    }

    #[test]
    fn a_bar_as_wide_as_it_is_thick_stays() {
        // A square bar 3 cells a side along z (the built-in thin scene's frame at 128³): its
        // field falls below the level 3 cells in, but its side faces lie in the box.
        let inside = |v: [f32; 3]| (v[0] - 12.0).abs() <= 1.5 && (v[1] - 12.0).abs() <= 1.5;
        let mut pts = Vec::new();
        for k in 0..12 {
            let z = 6.0 + k as f32;
            for j in 0..6 {
                let u = 10.6 + j as f32 * 0.5;
                pts.push(point([10.5, u, z], [1.0, 0.0, 0.0]));
                pts.push(point([13.5, u, z], [-1.0, 0.0, 0.0]));
                pts.push(point([u, 10.5, z], [0.0, 1.0, 0.0]));
                pts.push(point([u, 13.5, z], [0.0, -1.0, 0.0]));
            }
        }
        assert_none_move(|v| if inside(v) { 60.0 } else { 0.0 }, pts);
    }

    #[test]
    fn largest_share_matches_known_spectra() {
        // diag(3, 1, 0): 3/4.
        assert!((largest_share(&[3.0, 1.0, 0.0, 0.0, 0.0, 0.0]) - 0.75).abs() < 1e-12);
        // Parallel normals (1, 1, 0)/√2, any count: 1.
        let m = moments([
            std::f32::consts::FRAC_1_SQRT_2,
            std::f32::consts::FRAC_1_SQRT_2,
            0.0,
        ]);
        assert!((largest_share(&m.map(|x| 5.0 * x)) - 1.0).abs() < 1e-6);
        // Isotropic: 1/3; zero: 0.
        assert!((largest_share(&[2.0, 2.0, 2.0, 0.0, 0.0, 0.0]) - 1.0 / 3.0).abs() < 1e-12);
        assert_eq!(largest_share(&[0.0; 6]), 0.0);
        // A rotated diag(4, 2, 1) (rotation about z by 30°): 4/7.
        let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
        let (l1, l2) = (4.0, 2.0);
        let m = [
            l1 * c * c + l2 * s * s,
            l1 * s * s + l2 * c * c,
            1.0,
            (l1 - l2) * c * s,
            0.0,
            0.0,
        ];
        assert!((largest_share(&m) - 4.0 / 7.0).abs() < 1e-12);
    }
}
