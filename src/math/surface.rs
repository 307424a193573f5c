//! Stage-2 (αSurf) surface rendering pieces (method.md §3.2, §5): the twin of
//! `glsl/lib/surface.glsl` (same operations in the same order, no FMA contraction where the GLSL is
//! `precise` without `fma`).
//!
//! grid = p·scale + offset and the grid-space direction is normalised, so t and s are in voxels.
//! A cell's piece [t0, t1] of the DDA walk has entry point q0 = P(t0) − l and exit point
//! q1 = P(t1) − l with P(t) = og + t·dn, clamped to [0,1]³ with the coordinate nearest a face
//! snapped onto it: the exit of one cell and the entry of the next are the same global point, so a
//! level through a shared face is decided alike on both sides, and belongs to the entered cell.

use super::cubic::{cell_cubic, exit_point, solve_crossings, trilerp_level};
use super::dda::ray_unit;

/// At most this many levels τ_i.
pub const SURF_MAX_LEVELS: usize = 8;
/// Bound of a cell's hit list: ≤ 3 crossings per level.
pub const SURF_MAX_CELL_HITS: usize = 24;

/// Per-ray output of `surface_fwd` (`SurfOut` in the GLSL, scalar layout, 20 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct SurfOut {
    /// Colour on a white background.
    pub rgb: [f32; 3],
    /// Final transmittance (before the background is added).
    pub transmittance: f32,
    /// Front-face hits composited.
    pub hits: u32,
}

/// Scene ray (ro, rd) → grid origin `ro·scale + offset` and unit grid direction.
pub fn surf_ray(
    ro: [f32; 3],
    rd: [f32; 3],
    scale: [f32; 3],
    offset: [f32; 3],
) -> ([f32; 3], [f32; 3]) {
    let og = std::array::from_fn(|i| ro[i] * scale[i] + offset[i]);
    let dg = std::array::from_fn(|i| rd[i] * scale[i]);
    (og, ray_unit(dg))
}

/// Local coordinates in cell `l` of og + t·dn, clamped to [0,1]³, the coordinate nearest a face
/// snapped onto it within `cubic::SNAP`.
pub fn surf_local(og: [f32; 3], dn: [f32; 3], t: f32, l: [i32; 3]) -> [f32; 3] {
    let q = std::array::from_fn(|i| (og[i] + t * dn[i]) - l[i] as f32);
    exit_point(q, dn, 0.0)
}

/// A cell's sorted front-face hits (s values).
#[derive(Clone, Copy, Debug)]
pub struct CellHits {
    pub n: usize,
    pub s: [f32; SURF_MAX_CELL_HITS],
    /// Level index of each hit.
    pub level: [u32; SURF_MAX_CELL_HITS],
}

impl CellHits {
    fn insert(&mut self, s: f32, level: u32) {
        let mut i = self.n;
        while i > 0 && self.s[i - 1] > s {
            self.s[i] = self.s[i - 1];
            self.level[i] = self.level[i - 1];
            i -= 1;
        }
        self.s[i] = s;
        self.level[i] = level;
        self.n += 1;
    }

    /// The hits in order.
    pub fn as_slice(&self) -> &[f32] {
        &self.s[..self.n]
    }

    /// The level index of each hit, in the same order.
    pub fn levels(&self) -> &[u32] {
        &self.level[..self.n]
    }
}

/// Min/max culling: bit i set when `levels[i]` (at most [`SURF_MAX_LEVELS`]) lies within
/// [min c, max c]; only those levels can cross the cell.
pub fn surf_level_mask(c: &[f32; 8], levels: &[f32]) -> u32 {
    let cmin = c[0]
        .min(c[1])
        .min(c[2].min(c[3]))
        .min(c[4].min(c[5]).min(c[6].min(c[7])));
    let cmax = c[0]
        .max(c[1])
        .max(c[2].max(c[3]))
        .max(c[4].max(c[5]).max(c[6].max(c[7])));
    levels
        .iter()
        .take(SURF_MAX_LEVELS)
        .enumerate()
        .filter(|(_, &tau)| cmin <= tau && tau <= cmax)
        .fold(0, |m, (i, _)| m | 1 << i)
}

/// Front-face (rising) crossings in one cell of the levels in `mask` (from [`surf_level_mask`]),
/// sorted by s ∈ [0, L): corners `c` (paper order), entry/exit points, unit direction `d`. C1..C3
/// are formed once; each level solves with its own exact end values.
pub fn surf_cell_hits(
    c: &[f32; 8],
    q0: [f32; 3],
    q1: [f32; 3],
    d: [f32; 3],
    l: f32,
    levels: &[f32],
    mut mask: u32,
) -> CellHits {
    let cc = cell_cubic(c, q0, d);
    let mut out = CellHits {
        n: 0,
        s: [0.0; SURF_MAX_CELL_HITS],
        level: [0; SURF_MAX_CELL_HITS],
    };
    while mask != 0 {
        let i = mask.trailing_zeros() as usize;
        mask &= mask - 1;
        let tau = levels[i];
        let ends = [trilerp_level(c, q0, tau), trilerp_level(c, q1, tau)];
        let x = solve_crossings(cc, ends, l);
        for (s, rising) in x.iter() {
            if rising {
                out.insert(s, i as u32);
            }
        }
    }
    out
}

/// Truncation weight γ_a(j) = ½(1 − cos(π·clamp(a − j, 0, 1))): exactly 1 for j ≤ a − 1 and
/// exactly 0 for j ≥ a.
pub fn surf_gamma(a: f32, j: u32) -> f32 {
    let u = (a - j as f32).clamp(0.0, 1.0);
    if u >= 1.0 {
        return 1.0;
    }
    if u <= 0.0 {
        return 0.0;
    }
    0.5 * (1.0 - (std::f32::consts::PI * u).cos())
}

/// α = 1 − exp(−max(σα, 0)) (no step length).
pub fn surf_alpha(sa: f32) -> f32 {
    1.0 - (-sa.max(0.0)).exp()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gamma_ends_and_blend() {
        assert_eq!(surf_gamma(1.0, 0), 1.0);
        assert_eq!(surf_gamma(1.0, 1), 0.0);
        assert_eq!(surf_gamma(5.0, 4), 1.0);
        assert_eq!(surf_gamma(5.0, 5), 0.0);
        assert!((surf_gamma(2.5, 2) - 0.5).abs() < 1e-6);
        // cos(π/4) = √½: γ = ½(1 − √½).
        assert!((surf_gamma(2.25, 2) - 0.5 * (1.0 - 0.5f32.sqrt())).abs() < 1e-6);
        assert_eq!(surf_alpha(-3.0), 0.0);
    }

    #[test]
    fn cell_hits_sorted_front_faces_only() {
        // δ = x over the cell: along +x every level in (0, 1) is one rising crossing at s = τ;
        // along −x the same crossings fall (no hits).
        let c = [0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0];
        let levels = [0.7, 0.2, 0.5, 2.0];
        let mask = surf_level_mask(&c, &levels);
        assert_eq!(mask, 0b0111);
        let h = surf_cell_hits(
            &c,
            [0.0, 0.5, 0.5],
            [1.0, 0.5, 0.5],
            [1.0, 0.0, 0.0],
            1.0,
            &levels,
            mask,
        );
        assert_eq!(h.n, 3);
        for (s, want) in h.as_slice().iter().zip([0.2, 0.5, 0.7]) {
            assert!((s - want).abs() < 1e-6, "{s} {want}");
        }
        let h = surf_cell_hits(
            &c,
            [1.0, 0.5, 0.5],
            [0.0, 0.5, 0.5],
            [-1.0, 0.0, 0.0],
            1.0,
            &levels,
            mask,
        );
        assert_eq!(h.n, 0);
    }
}
