//! The surface colour written with extracted points and meshes: the grid's view-independent
//! colour, SH band 0 (C₀·k₀ + 0.5 per channel, as the renderer's colour without its
//! direction-dependent bands), trilinear between the allocated corners of the cell, clamped to
//! [0, 1] and rounded to 8 bits (PLY `red green blue`, as MeshLab and Blender read them).

use crate::math::sh::SH_C0;
use crate::math::trilerp::trilerp;

/// A grid's SH coefficients, 27 per allocated vertex `[R0..R8, G0..G8, B0..B8]`.
pub struct Band0<'a> {
    pub res: [u32; 3],
    pub links: &'a [i32],
    pub sh: &'a [f32],
}

impl Band0<'_> {
    /// The 8-bit colour at grid position `g` (vertex units): trilinear over the allocated corners
    /// of the cell holding it (weights renormalised; mid grey where none is allocated).
    pub fn rgb_at(&self, g: [f32; 3]) -> [u8; 3] {
        let base: [usize; 3] = std::array::from_fn(|i| {
            (g[i].floor().max(0.0) as usize).min(self.res[i].saturating_sub(2) as usize)
        });
        let local: [f32; 3] = std::array::from_fn(|i| (g[i] - base[i] as f32).clamp(0.0, 1.0));
        let [_, ry, rz] = self.res.map(|r| r as usize);
        let (mut k0, mut have) = ([[0f32; 8]; 3], [0f32; 8]);
        for k in 0..8 {
            let q = [
                base[0] + (k >> 2),
                base[1] + ((k >> 1) & 1),
                base[2] + (k & 1),
            ];
            let l = self.links[(q[0] * ry + q[1]) * rz + q[2]];
            if l >= 0 {
                have[k] = 1.0;
                for (c, ch) in k0.iter_mut().enumerate() {
                    ch[k] = self.sh[27 * l as usize + 9 * c];
                }
            }
        }
        let weight = trilerp(&have, local);
        if weight <= 0.0 {
            return [128; 3];
        }
        k0.map(|ch| {
            let v = SH_C0 * trilerp(&ch, local) / weight + 0.5;
            (v.clamp(0.0, 1.0) * 255.0).round() as u8
        })
    }
}
