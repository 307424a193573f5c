//! The outermost level's halo: where a part is thick enough for the field to reach a higher level
//! just inside the outermost level's surface, the higher level set locates the part's surface
//! better, and the outermost one is a shell around it (about a cell out on thin objects' wires
//! and solids). A point of the outermost level is dropped when, within `reach` cells inward along
//! its normal (toward increasing field), the trilinear field reaches the level two above it; where
//! the part is too thin for that (the field's peak stays between the two), the outermost level is
//! the only surface there and stays.

use crate::abi::extract::ExtractPoint;
use crate::eval::extract::grid_position;
use crate::math::trilerp::trilerp;
use rayon::prelude::*;
use std::ops::RangeInclusive;

/// Cells inward along the normal within which the higher level is looked for.
pub const REACH: f32 = 1.5;
/// Steps per cell of the searches along a normal (this one and `eval::sheets`').
pub const STEPS_PER_CELL: f32 = 10.0;

/// The field on a grid of `res` vertices (values by `links`, −1: unallocated).
pub struct Field<'a> {
    pub res: [u32; 3],
    pub links: &'a [i32],
    pub values: &'a [f32],
}

impl Field<'_> {
    /// The trilinear value at grid position `g`, or None where a corner is outside the grid or
    /// unallocated.
    fn at(&self, g: [f32; 3]) -> Option<f32> {
        let base: [i64; 3] = std::array::from_fn(|i| g[i].floor() as i64);
        if (0..3).any(|i| base[i] < 0 || base[i] + 1 >= self.res[i] as i64) {
            return None;
        }
        let [_, ry, rz] = self.res.map(|r| r as usize);
        let mut c = [0f32; 8];
        for (k, v) in c.iter_mut().enumerate() {
            let q = [
                base[0] as usize + (k >> 2),
                base[1] as usize + ((k >> 1) & 1),
                base[2] as usize + (k & 1),
            ];
            let l = self.links[(q[0] * ry + q[1]) * rz + q[2]];
            if l < 0 {
                return None;
            }
            *v = self.values[l as usize];
        }
        Some(trilerp(&c, std::array::from_fn(|i| g[i] - base[i] as f32)))
    }

    /// Whether the field reaches `tau` within `reach` cells of point `p` along its gradient.
    fn point_reaches(&self, p: &ExtractPoint, tau: f32, reach: f32) -> bool {
        self.reaches(grid_position(self.res, p), p.grad, tau, reach)
    }

    /// The distances t = k / STEPS_PER_CELL for k in `steps` along the unit direction `n` from
    /// grid position `o`, each with the field there (None: a corner outside or unallocated).
    fn along(
        &self,
        o: [f32; 3],
        n: [f32; 3],
        steps: RangeInclusive<u32>,
    ) -> impl Iterator<Item = (f32, Option<f32>)> + '_ {
        steps.map(move |k| {
            let t = k as f32 / STEPS_PER_CELL;
            (t, self.at(std::array::from_fn(|i| o[i] + t * n[i])))
        })
    }

    /// The first distance in [`from`, `reach`] cells, on the lattice of STEPS_PER_CELL per cell,
    /// along the unit direction `n` from grid position `o` at which the field is below `tau` or
    /// undefined (an unallocated or outside corner: empty space); None where it stays at or
    /// above `tau`.
    pub fn falls_below(
        &self,
        o: [f32; 3],
        n: [f32; 3],
        tau: f32,
        from: f32,
        reach: f32,
    ) -> Option<f32> {
        let first = (from * STEPS_PER_CELL).ceil() as u32;
        let last = (reach * STEPS_PER_CELL).round() as u32;
        self.along(o, n, first..=last)
            .find(|(_, x)| x.is_none_or(|x| x < tau))
            .map(|(t, _)| t)
    }

    /// Whether the field reaches `tau` within `reach` cells of grid position `o` along the
    /// direction `dir` (grid coordinates, any length).
    pub fn reaches(&self, o: [f32; 3], dir: [f32; 3], tau: f32, reach: f32) -> bool {
        let Some(n) = unit(dir) else {
            return false;
        };
        let steps = (reach * STEPS_PER_CELL).round() as u32;
        self.along(o, n, 1..=steps)
            .any(|(_, x)| x.is_some_and(|x| x >= tau))
    }
}

/// `g` scaled to unit length; None for a zero or non-finite vector (no direction to search).
pub fn unit(g: [f32; 3]) -> Option<[f32; 3]> {
    let len = g.iter().map(|x| x * x).sum::<f32>().sqrt();
    (len > 0.0 && len.is_finite()).then(|| g.map(|x| x / len))
}

/// Keep `points` except the outermost level's where the level two above it lies within `reach`
/// cells inward; returns how many were dropped. Fewer than three levels: nothing to do.
pub fn drop_outer_halo(
    points: &mut Vec<ExtractPoint>,
    field: &Field,
    levels: &[f32],
    reach: f32,
) -> usize {
    if levels.len() < 3 {
        return 0;
    }
    let tau = levels[2];
    let halo: Vec<bool> = points
        .par_iter()
        .map(|p| p.level == 0 && field.point_reaches(p, tau, reach))
        .collect();
    let mut i = 0;
    points.retain(|_| {
        i += 1;
        !halo[i - 1]
    });
    halo.iter().filter(|&&h| h).count()
}

#[cfg(test)]
mod tests {
    use super::*;

    const RES: [u32; 3] = [16, 16, 16];

    /// A field that depends on x only, f(x) = profile(x), on every vertex.
    fn field_of(profile: impl Fn(usize) -> f32) -> (Vec<i32>, Vec<f32>) {
        let n = (RES[0] * RES[1] * RES[2]) as usize;
        let links = (0..n as i32).collect();
        let values = (0..n)
            .map(|s| profile(s / (RES[1] * RES[2]) as usize))
            .collect();
        (links, values)
    }

    fn field<'a>(links: &'a [i32], values: &'a [f32]) -> Field<'a> {
        Field {
            res: RES,
            links,
            values,
        }
    }

    fn point(x: f32, level: u32) -> ExtractPoint {
        let cell = x.floor() as u32;
        ExtractPoint {
            local: [x - cell as f32, 0.5, 0.5],
            grad: [1.0, 0.0, 0.0],
            alpha: 1.0,
            cell: (cell * RES[1] + 8) * RES[2] + 8,
            level,
            ray: 0,
        }
    }

    #[test]
    fn a_thick_part_loses_its_outer_level_and_a_thin_one_keeps_it() {
        let levels = [10.0, 30.0, 50.0];
        // Thick: a ramp of 40 a cell from x = 4, the outer level at x = 4.25, the third (50) at
        // 5.25, a cell further in.
        let (links, values) = field_of(|x| (40.0 * (x as f32 - 4.0)).clamp(0.0, 80.0));
        let f = field(&links, &values);
        let mut pts = vec![point(4.25, 0), point(4.75, 1), point(5.25, 2)];
        assert_eq!(drop_outer_halo(&mut pts, &f, &levels, REACH), 1);
        assert_eq!(pts.iter().map(|p| p.level).collect::<Vec<_>>(), [1, 2]);
        // Thin: a peak of 40 at x = 6, never reaching 50.
        let (links, values) = field_of(|x| if x == 6 { 40.0 } else { 0.0 });
        let f = field(&links, &values);
        let mut pts = vec![point(5.25, 0)];
        assert_eq!(drop_outer_halo(&mut pts, &f, &levels, REACH), 0);
        // The ramp 2 cells further in than the reach: the outer level stays too.
        let (links, values) = field_of(|x| if x >= 8 { 60.0 } else { 10.0 });
        let f = field(&links, &values);
        let mut pts = vec![point(5.0, 0)];
        assert_eq!(drop_outer_halo(&mut pts, &f, &levels, REACH), 0);
        // Two levels only: nothing to compare with.
        let mut pts = vec![point(4.5, 0)];
        assert_eq!(drop_outer_halo(&mut pts, &f, &levels[..2], REACH), 0);
    }

    #[test]
    fn unallocated_corners_never_reach() {
        let (mut links, values) = field_of(|x| (20.0 * (x as f32 - 4.0)).clamp(0.0, 60.0));
        // Remove the vertices from x = 5 on: the search meets no allocated cell inward.
        let plane = (RES[1] * RES[2]) as usize;
        links[5 * plane..].iter_mut().for_each(|l| *l = -1);
        let f = field(&links, &values);
        let mut pts = vec![point(4.5, 0)];
        assert_eq!(drop_outer_halo(&mut pts, &f, &[10.0, 30.0, 50.0], REACH), 0);
    }
}
