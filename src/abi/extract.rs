//! What `glsl/extract_points.comp` is given and what it writes.

/// One extracted point, laid out as the kernel writes it (`glsl/lib/extract.glsl`, 40 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ExtractPoint {
    /// Position inside the cell, [0,1]³.
    pub local: [f32; 3],
    /// Gradient of the trilerped field with respect to `local` (not normalised).
    pub grad: [f32; 3],
    /// 1 − exp(−max(σα, 0)) at the point; 1 without an opacity field.
    pub alpha: f32,
    /// `links` slot of the cell's corner 000.
    pub cell: u32,
    /// Index into the level list.
    pub level: u32,
    /// axis·R² + iu·R + iv.
    pub ray: u32,
}

impl ExtractPoint {
    /// The (cell, level, ray) slot: unique per point (one point per ray and level at most).
    pub fn key(&self) -> (u32, u32, u32) {
        (self.cell, self.level, self.ray)
    }
}

/// Inputs of the kernel (the push-constant block, as slices).
#[derive(Clone, Copy, Debug)]
pub struct ExtractInput<'a> {
    /// `links` slot of corner 000 of each cell to visit (all 8 corners allocated).
    pub cells: &'a [u32],
    /// Index volume, X·Y·Z, < 0 empty.
    pub links: &'a [i32],
    /// Scalar field per allocated vertex (σ for stage 1, δ for stage 2).
    pub field: &'a [f32],
    /// Raw opacity σα per allocated vertex, or `None` (no opacity test, α = 1).
    pub opacity: Option<&'a [f32]>,
    /// Level values τ.
    pub levels: &'a [f32],
    /// Vertices per axis.
    pub res: [u32; 3],
    /// R: rays per axis and face dimension (R² rays per axis).
    pub rays_per_axis: u32,
    /// Keep a crossing only when the trilerped σα ≥ this (ignored without `opacity`).
    pub min_opacity: f32,
}
