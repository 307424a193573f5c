//! Hidden surfaces: which cells of an extraction hold surfaces that no training view sees and
//! that other surfaces enclose.
//!
//! A level-set extraction returns every level crossing whose opacity passes the threshold,
//! including the inner level sets of solids (a sound box's or a motor housing's interior), whose
//! opacity no ray ever trains. A cell that holds points is kept when
//! - some training camera sees it: the straight line from the cell's centre to the camera's
//!   centre crosses no other occupied cell (past the first `skip` cells, which belong to the
//!   cell's own surface), or
//! - it lies open: at least `min_open` of `directions` fixed directions (a Fibonacci sphere) leave
//!   the grid the same way, as below a never-seen underside;
//!
//! and dropped otherwise. The lines are marched in half-cell steps through the occupancy of the
//! extracted cells themselves, so what hides a cell is the extracted surfaces, at any opacity:
//! this suits opaque (thin) objects, not semi-transparent layers, which the views see through.

use crate::grid::slot_vertex;
use rayon::prelude::*;

/// A training camera as the trimming looks toward it from a cell: a point of grid space in
/// homogeneous coordinates [x, y, z, w]. From a cell centre c the line toward it runs along
/// (x, y, z) − w·c; with w > 0 it ends at (x, y, z)/w, with w ≤ 0 it leaves the grid first (a
/// camera a projective grid such as NDC puts at or beyond infinity).
pub type Viewpoint = [f32; 4];

/// The trimming's parameters (in cells of the grid).
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct HiddenTrim {
    /// Distance along a line, in cells, within which occupied cells do not hide (the cell's own
    /// surface and its neighbouring level sets).
    pub skip: f32,
    /// Directions tried for an open cell.
    pub directions: u32,
    /// Share of the directions that must leave the grid for a cell unseen by every camera.
    pub min_open: f32,
}

impl Default for HiddenTrim {
    fn default() -> Self {
        HiddenTrim {
            skip: 2.5,
            directions: 48,
            min_open: 0.1,
        }
    }
}

/// What the trimming found.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct HiddenStats {
    /// Occupied cells.
    pub cells: usize,
    /// Cells some training camera sees.
    pub seen: usize,
    /// Cells no camera sees but open in enough directions.
    pub open: usize,
    /// Cells dropped.
    pub hidden: usize,
    pub wall_ms: f64,
}

/// Occupied cells of a grid of `res` vertices per axis, as a bit per vertex slot (a cell is named
/// by the slot of its corner 000, as the extraction names it).
pub struct Occupancy {
    res: [u32; 3],
    bits: Vec<u64>,
}

impl Occupancy {
    /// The cells `cells` (corner-000 slots; each < res³) of a grid of `res` vertices.
    pub fn new(res: [u32; 3], cells: impl IntoIterator<Item = u32>) -> Occupancy {
        let slots = res.iter().map(|&r| r as usize).product::<usize>();
        let mut bits = vec![0u64; slots.div_ceil(64)];
        for c in cells {
            bits[c as usize / 64] |= 1 << (c % 64);
        }
        Occupancy { res, bits }
    }

    fn slot(&self, c: [i64; 3]) -> usize {
        let [_, ry, rz] = self.res.map(|r| r as usize);
        (c[0] as usize * ry + c[1] as usize) * rz + c[2] as usize
    }

    fn contains(&self, c: [i64; 3]) -> bool {
        self.holds(self.slot(c) as u32)
    }

    /// Whether the cell with corner-000 slot `slot` is occupied.
    pub fn holds(&self, slot: u32) -> bool {
        let s = slot as usize;
        self.bits[s / 64] >> (s % 64) & 1 != 0
    }

    /// Whether cell `c` (0 ≤ c < res − 1 per axis) exists.
    fn is_cell(&self, c: [i64; 3]) -> bool {
        (0..3).all(|i| c[i] >= 0 && c[i] < self.res[i] as i64 - 1)
    }

    /// March from the centre of `cell` along the unit direction `d` (grid coordinates) in
    /// half-cell steps, from `skip` on, until `max_t` or out of the grid: true when no occupied
    /// cell other than `cell` is met.
    fn clear(&self, cell: [i64; 3], d: [f32; 3], skip: f32, max_t: f32) -> bool {
        let o = cell.map(|c| c as f32 + 0.5);
        let mut t = skip;
        while t < max_t {
            let q: [i64; 3] = std::array::from_fn(|i| (o[i] + t * d[i]).floor() as i64);
            if !self.is_cell(q) {
                return true;
            }
            if q != cell && self.contains(q) {
                return false;
            }
            t += 0.5;
        }
        true
    }

    fn coords(&self, slot: u32) -> [i64; 3] {
        slot_vertex(self.res, slot as usize).map(|v| v as i64)
    }
}

/// `n` unit directions spread evenly over the sphere (a Fibonacci lattice).
pub fn sphere_directions(n: u32) -> Vec<[f32; 3]> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - (2.0 * i as f64 + 1.0) / n as f64;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = golden * i as f64;
            [(r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32]
        })
        .collect()
}

/// The cells to keep of a grid of `res` vertices whose points (or faces) lie in the cells
/// `item_cells` (corner-000 slots, one per item, in any order and repeated): those seen from one
/// of `cameras` or open (see the module comment).
pub fn kept_cells(
    res: [u32; 3],
    item_cells: &[u32],
    cameras: &[Viewpoint],
    t: &HiddenTrim,
) -> (Occupancy, HiddenStats) {
    let mut cells = item_cells.to_vec();
    cells.par_sort_unstable();
    cells.dedup();
    let occ = Occupancy::new(res, cells.iter().copied());
    let (keep, stats) = visible_cells(&occ, &cells, cameras, t);
    let kept = cells.iter().zip(&keep).filter(|(_, &k)| k).map(|(&c, _)| c);
    (Occupancy::new(res, kept), stats)
}

/// For each of `cells` (corner-000 slots of the occupied cells), whether to keep it: seen from
/// one of `cameras` or open (see the module comment).
fn visible_cells(
    occ: &Occupancy,
    cells: &[u32],
    cameras: &[Viewpoint],
    t: &HiddenTrim,
) -> (Vec<bool>, HiddenStats) {
    let t0 = std::time::Instant::now();
    let dirs = sphere_directions(t.directions);
    let need = (t.min_open * t.directions as f32).ceil().max(1.0) as usize;
    let far = occ.res.iter().map(|&r| r as f32).sum::<f32>();
    // 0: hidden, 1: seen, 2: open.
    let verdict: Vec<u8> = cells
        .par_iter()
        .map(|&s| {
            let c = occ.coords(s);
            let centre = c.map(|v| v as f32 + 0.5);
            let seen = cameras.iter().any(|cam| {
                let d: [f32; 3] = std::array::from_fn(|i| cam[i] - cam[3] * centre[i]);
                let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                // The distance to a finite camera is len / w; one at infinity lies past the grid.
                let reach = if cam[3] > 0.0 { len / cam[3] } else { far };
                len > 0.0 && occ.clear(c, d.map(|x| x / len), t.skip, reach)
            });
            if seen {
                return 1;
            }
            let mut open = 0;
            for d in &dirs {
                if occ.clear(c, *d, t.skip, far) {
                    open += 1;
                    if open >= need {
                        return 2;
                    }
                }
            }
            0
        })
        .collect();
    let count = |v: u8| verdict.iter().filter(|&&x| x == v).count();
    let stats = HiddenStats {
        cells: cells.len(),
        seen: count(1),
        open: count(2),
        hidden: count(0),
        wall_ms: t0.elapsed().as_secs_f64() * 1e3,
    };
    (verdict.into_iter().map(|v| v != 0).collect(), stats)
}

#[cfg(test)]
mod tests {
    use super::*;

    const RES: [u32; 3] = [33, 33, 33];

    fn slot(c: [u32; 3]) -> u32 {
        (c[0] * RES[1] + c[1]) * RES[2] + c[2]
    }

    /// The cells of the box lo..hi per axis (hi excluded), in x, y, z order.
    fn cuboid(lo: [u32; 3], hi: [u32; 3]) -> Vec<[u32; 3]> {
        let mut v = Vec::new();
        for i in lo[0]..hi[0] {
            for j in lo[1]..hi[1] {
                for k in lo[2]..hi[2] {
                    v.push([i, j, k]);
                }
            }
        }
        v
    }

    /// The cells of a closed cubic shell [lo, hi]³ (its faces one cell thick).
    fn shell(lo: u32, hi: u32) -> Vec<u32> {
        cuboid([lo; 3], [hi + 1; 3])
            .into_iter()
            .filter(|c| c.iter().any(|&x| x == lo || x == hi))
            .map(slot)
            .collect()
    }

    fn keep_of(cells: &[u32], cameras: &[[f32; 3]]) -> Vec<bool> {
        let points: Vec<Viewpoint> = cameras.iter().map(|c| [c[0], c[1], c[2], 1.0]).collect();
        keep_from(cells, &points)
    }

    fn keep_from(cells: &[u32], cameras: &[Viewpoint]) -> Vec<bool> {
        let occ = Occupancy::new(RES, cells.iter().copied());
        visible_cells(&occ, cells, cameras, &HiddenTrim::default()).0
    }

    #[test]
    fn directions_are_unit_and_balanced() {
        let d = sphere_directions(48);
        let mut sum = [0f64; 3];
        for v in &d {
            let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            assert!((n - 1.0).abs() < 1e-5, "{v:?}");
            (0..3).for_each(|i| sum[i] += v[i] as f64);
        }
        assert!(sum.iter().all(|s| s.abs() < 0.5), "{sum:?}");
    }

    const AROUND: [[f32; 3]; 6] = [
        [-20.0, 16.5, 16.5],
        [52.0, 16.5, 16.5],
        [16.5, -20.0, 16.5],
        [16.5, 52.0, 16.5],
        [16.5, 16.5, -20.0],
        [16.5, 16.5, 52.0],
    ];

    #[test]
    fn a_shell_inside_a_closed_shell_is_hidden_and_the_outer_one_is_seen() {
        let outer = shell(4, 28);
        let inner = shell(12, 20);
        let all: Vec<u32> = outer.iter().chain(&inner).copied().collect();
        let keep = keep_of(&all, &AROUND);
        let (k_out, k_in) = keep.split_at(outer.len());
        assert!(k_out.iter().all(|&k| k), "an outer cell was dropped");
        assert!(k_in.iter().all(|&k| !k), "an enclosed inner cell was kept");
        // Without the outer shell every inner cell is seen.
        assert!(keep_of(&inner, &AROUND).iter().all(|&k| k));
    }

    #[test]
    fn the_core_of_a_solid_block_is_hidden() {
        let block: Vec<u32> = cuboid([6; 3], [26; 3]).into_iter().map(slot).collect();
        let keep = keep_of(&block, &AROUND);
        let at = |c| block.iter().position(|&s| s == slot(c)).unwrap();
        assert!(!keep[at([16, 16, 16])], "the core was kept");
        assert!(keep[at([6, 16, 16])], "a face cell was dropped");
    }

    #[test]
    fn an_unseen_underside_open_below_is_kept() {
        // A slab seen only from above (+z): no camera sees its bottom face, which is open below.
        let slab: Vec<u32> = cuboid([8, 8, 8], [24, 24, 12])
            .into_iter()
            .map(slot)
            .collect();
        let keep = keep_of(&slab, &[[16.5, 16.5, 60.0], [40.0, 16.5, 50.0]]);
        let bottom: Vec<bool> = slab
            .iter()
            .zip(&keep)
            .filter(|(&s, _)| s % RES[2] == 8)
            .map(|(_, &k)| k)
            .collect();
        assert_eq!(bottom.len(), 16 * 16);
        assert!(bottom.iter().all(|&k| k), "the open underside was dropped");
    }

    /// A camera in homogeneous coordinates: the same point scaled by w > 0 sees what it sees;
    /// one at infinity (w = 0) sees along its direction from every cell, as a projective grid's
    /// (NDC's) cameras do, and one past infinity (w < 0) along the opposite of (x, y, z) − w·c.
    #[test]
    fn cameras_at_infinity_see_along_their_direction() {
        let all: Vec<u32> = shell(4, 28).into_iter().chain(shell(12, 20)).collect();
        let above = [16.5f32, 16.5, 60.0];
        let finite = keep_of(&all, &[above]);
        assert_eq!(keep_from(&all, &[[33.0, 33.0, 120.0, 2.0]]), finite);
        // Straight up from every cell (w = 0), and straight down (w < 0: reached through
        // infinity): the outer roof (floor) seen, the inner one hidden by it.
        let at = |c| all.iter().position(|&s| s == slot(c)).unwrap();
        for (cam, outer, inner) in [
            ([0.0, 0.0, 1.0, 0.0], 28, 20),
            ([0.0, 0.0, -1.0, -1e-9], 4, 12),
        ] {
            let keep = keep_from(&all, &[cam]);
            assert!(
                keep[at([16, 16, outer])],
                "{cam:?}: the outer face was dropped"
            );
            assert!(
                !keep[at([16, 16, inner])],
                "{cam:?}: the inner face was kept"
            );
        }
    }

    #[test]
    fn a_box_open_below_keeps_the_floor_of_what_it_encloses() {
        // A box without its floor around a closed shell, seen from above only: the inner shell's
        // floor is open downwards through the missing floor; its roof is hidden.
        let is_floor = |s: u32| {
            let (i, j, k) = (s / (RES[1] * RES[2]), (s / RES[2]) % RES[1], s % RES[2]);
            k == 4 && i > 4 && i < 28 && j > 4 && j < 28
        };
        let cells: Vec<u32> = shell(4, 28)
            .into_iter()
            .filter(|&s| !is_floor(s))
            .chain(shell(12, 20))
            .collect();
        let keep = keep_of(&cells, &[[16.5, 16.5, 60.0]]);
        let at = |c| cells.iter().position(|&s| s == slot(c)).unwrap();
        assert!(
            keep[at([16, 16, 12])],
            "the inner floor, open below, was dropped"
        );
        assert!(
            !keep[at([16, 16, 20])],
            "the inner roof, enclosed, was kept"
        );
    }
}
