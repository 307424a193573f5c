//! The stage-2 grid as the surface kernels read it: borrowed arrays in the layout of their storage
//! buffers, made by the grid that owns them (`grid::surface`) and read by the CPU twins.

use anyhow::{ensure, Result};
use rayon::prelude::*;

/// Borrowed stage-2 grid: `n`³ vertices (x-major links, < 0 unallocated) and per allocated vertex
/// δ, raw opacity σα and 27 SH coefficients.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceGridRef<'a> {
    pub n: u32,
    pub links: &'a [i32],
    pub delta: &'a [f32],
    pub opacity: &'a [f32],
    pub sh: &'a [f32],
    /// The links are known to be below the row count (a caller that checked them once and keeps
    /// them unchanged); `validate` then skips its O(n³) scan.
    pub links_checked: bool,
}

impl SurfaceGridRef<'_> {
    /// Checks the array sizes against each other and, unless `links_checked`, that every link is
    /// below the row count (user input never panics in the kernels).
    pub fn validate(&self) -> Result<()> {
        let n = self.n as usize;
        ensure!(self.n >= 2, "surface grid needs n ≥ 2, got {}", self.n);
        ensure!(
            self.links.len() == n * n * n,
            "links has {} entries, want {}",
            self.links.len(),
            n * n * n
        );
        let rows = self.delta.len();
        ensure!(
            self.opacity.len() == rows && self.sh.len() == 27 * rows,
            "per-vertex arrays disagree: {} δ, {} σα, {} SH",
            rows,
            self.opacity.len(),
            self.sh.len()
        );
        ensure!(
            self.links_checked || self.links.par_iter().all(|&l| l < rows as i32),
            "a link points past the {rows} vertex rows"
        );
        Ok(())
    }
}
