//! Sparse voxel grid (svox2 layout): an index volume `links` (one i32 per vertex; ≥ 0 is a row in
//! the compact per-vertex arrays, < 0 is empty) plus structure-of-arrays data: density σ and 27 SH
//! coefficients per vertex ([R0..R8, G0..G8, B0..B8]). Vertex (x, y, z) of an X×Y×Z grid sits at
//! `links[(x·Y + y)·Z + z]`. World→grid: g = ((p − c)/(2r) + 0.5)·N − 0.5 per axis.

mod mask;
pub mod npz;
mod resample;
pub mod surface;

pub use mask::{cells_then_corners, dilate};
pub use resample::upsample;

/// Coefficients per vertex: 3 channels × 9 degree-2 SH basis functions.
pub const SH_DIM: usize = 27;

/// The Plenoxels density + SH grid.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid {
    /// Vertices per axis.
    pub res: [u32; 3],
    /// Scene-space centre of the box.
    pub center: [f32; 3],
    /// Scene-space half-extent of the box per axis.
    pub radius: [f32; 3],
    /// Row of each vertex in the compact arrays, or < 0 when unallocated.
    pub links: Vec<i32>,
    /// σ per allocated vertex.
    pub density: Vec<f32>,
    /// 27 SH coefficients per allocated vertex.
    pub sh: Vec<f32>,
}

/// Vertex coordinates (x, y, z) of index `slot` into the `links` of a grid of `res` vertices
/// (x-major, z fastest).
pub fn slot_vertex(res: [u32; 3], slot: usize) -> [u32; 3] {
    let (ry, rz) = (res[1] as usize, res[2] as usize);
    [
        (slot / (ry * rz)) as u32,
        ((slot / rz) % ry) as u32,
        (slot % rz) as u32,
    ]
}

/// The slot of each of `rows` vertex rows (the inverse of `links`); 0 for a row no link names.
pub fn row_slots(links: &[i32], rows: usize) -> Vec<u32> {
    let mut out = vec![0u32; rows];
    for (s, &l) in links.iter().enumerate() {
        if l >= 0 {
            out[l as usize] = s as u32;
        }
    }
    out
}

/// Bytes a copy of a training state holds (what a checkpoint writes): `slots` links, and `rows`
/// vertices of `channels` floats each, twice (the values and their RMSProp averages).
pub fn state_bytes(slots: u64, rows: u64, channels: u64) -> u64 {
    4 * (slots + 2 * rows * channels)
}

/// A sparse grid as an optimiser sees it: the links and the per-vertex arrays it steps (in the
/// order of the stage's running averages), apart from the rest (resolution, placement, …).
pub trait SparseArrays: Clone {
    /// Row of each vertex slot, < 0 where none is allocated.
    fn links(&self) -> &[i32];
    /// Allocated vertex rows.
    fn rows(&self) -> usize;
    /// The optimised arrays, in order.
    fn arrays(&self) -> Vec<&[f32]>;
    /// The grid without its links and arrays.
    fn without_arrays(self) -> Self;
    /// The grid with `links` and `arrays` (in the order of [`Self::arrays`]) for its own.
    fn with_arrays(self, links: Vec<i32>, arrays: Vec<Vec<f32>>) -> anyhow::Result<Self>;
}

impl SparseArrays for Grid {
    fn links(&self) -> &[i32] {
        &self.links
    }

    fn rows(&self) -> usize {
        self.allocated()
    }

    /// σ, SH.
    fn arrays(&self) -> Vec<&[f32]> {
        vec![&self.density, &self.sh]
    }

    fn without_arrays(self) -> Grid {
        Grid {
            links: Vec::new(),
            density: Vec::new(),
            sh: Vec::new(),
            ..self
        }
    }

    fn with_arrays(self, links: Vec<i32>, arrays: Vec<Vec<f32>>) -> anyhow::Result<Grid> {
        let [density, sh] = arrays
            .try_into()
            .map_err(|a: Vec<_>| anyhow::anyhow!("{} arrays for a grid of 2", a.len()))?;
        Ok(Grid {
            links,
            density,
            sh,
            ..self
        })
    }
}

/// Which vertices a new stage-1 grid allocates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InitialFill {
    /// Those inside the box's inscribed sphere (svox2's initialisation, for a box with a margin
    /// around the object).
    Sphere,
    /// Every vertex: a box fitted to the object (a capture's foreground box) has its object's
    /// corners (a plinth's rim) and what the object stands on in its corners, outside the
    /// inscribed sphere (docs/results.md).
    Box,
}

impl InitialFill {
    /// The allocated region's radius relative to the box's half-size (√3 takes every vertex:
    /// they lie inside the box).
    pub fn radius(self) -> f32 {
        match self {
            InitialFill::Sphere => 1.0,
            InitialFill::Box => 3f32.sqrt(),
        }
    }

    /// The share of the grid's vertices allocated (of a fine grid).
    pub fn share(self) -> f64 {
        match self {
            InitialFill::Sphere => std::f64::consts::FRAC_PI_6,
            InitialFill::Box => 1.0,
        }
    }
}

impl Grid {
    /// Total number of vertex slots in `links`.
    pub fn slots(&self) -> usize {
        self.res.iter().map(|&r| r as usize).product()
    }

    /// Number of allocated vertices.
    pub fn allocated(&self) -> usize {
        self.density.len()
    }

    /// Index into `links` of vertex (x, y, z).
    pub fn slot(&self, x: u32, y: u32, z: u32) -> usize {
        ((x as usize * self.res[1] as usize) + y as usize) * self.res[2] as usize + z as usize
    }

    /// Vertex coordinates of a `links` index.
    pub fn vertex(&self, slot: usize) -> [u32; 3] {
        slot_vertex(self.res, slot)
    }

    /// Scene position → continuous grid coordinates.
    pub fn world_to_grid(&self, p: [f32; 3]) -> [f32; 3] {
        std::array::from_fn(|i| {
            ((p[i] - self.center[i]) / (2.0 * self.radius[i]) + 0.5) * self.res[i] as f32 - 0.5
        })
    }

    /// Continuous grid coordinates → scene position.
    pub fn grid_to_world(&self, g: [f32; 3]) -> [f32; 3] {
        std::array::from_fn(|i| {
            ((g[i] + 0.5) / self.res[i] as f32 - 0.5) * 2.0 * self.radius[i] + self.center[i]
        })
    }

    /// A grid of `res`³ vertices over the box (center, radius) with every vertex whose scene
    /// position lies inside the sphere of `sphere_radius` (relative to the box's half-extent)
    /// allocated with σ = `sigma` and SH = 0, as in svox2's sphere-bounded initialisation.
    pub fn sphere(
        res: u32,
        center: [f32; 3],
        radius: [f32; 3],
        sphere_radius: f32,
        sigma: f32,
    ) -> Grid {
        let mut g = Grid {
            res: [res; 3],
            center,
            radius,
            links: Vec::new(),
            density: Vec::new(),
            sh: Vec::new(),
        };
        let mut links = vec![-1i32; g.slots()];
        let mut n = 0i32;
        for (slot, link) in links.iter_mut().enumerate() {
            let v = g.vertex(slot);
            let w = g.grid_to_world([v[0] as f32, v[1] as f32, v[2] as f32]);
            let r2: f32 = (0..3)
                .map(|i| ((w[i] - center[i]) / radius[i]).powi(2))
                .sum();
            if r2 <= sphere_radius * sphere_radius {
                *link = n;
                n += 1;
            }
        }
        g.links = links;
        g.density = vec![sigma; n as usize];
        g.sh = vec![0.0; n as usize * SH_DIM];
        g
    }

    /// Keep only the vertices where `keep[slot]` is true, compacting the arrays in slot order.
    pub fn retain(&mut self, keep: &[bool]) {
        let mut density = Vec::new();
        let mut sh = Vec::new();
        for (slot, link) in self.links.iter_mut().enumerate() {
            if *link >= 0 && keep[slot] {
                let row = *link as usize;
                *link = density.len() as i32;
                density.push(self.density[row]);
                sh.extend_from_slice(&self.sh[row * SH_DIM..(row + 1) * SH_DIM]);
            } else {
                *link = -1;
            }
        }
        self.density = density;
        self.sh = sh;
    }

    /// Bytes a grid of `res` vertices with `rows` of them allocated takes while it trains: what
    /// a checkpoint holds (links, values, RMSProp's running averages) plus the gradient
    /// accumulators (one float per parameter).
    pub fn training_bytes(res: [u32; 3], rows: usize) -> f64 {
        let slots = res.iter().map(|&r| r as u64).product();
        let channels = 1 + SH_DIM as u64;
        (state_bytes(slots, rows as u64, channels) + 4 * rows as u64 * channels) as f64
    }

    /// Check the invariants a loaded grid must satisfy; the error says which one fails.
    pub fn validate(&self) -> Result<(), String> {
        // One cell needs two vertices per axis; the renderers and their twins index a cell's
        // far corner, which does not exist on a 1-vertex axis.
        if self.res.iter().any(|&r| r < 2) {
            return Err(format!(
                "resolution {:?}: every axis needs at least 2 vertices (one cell)",
                self.res
            ));
        }
        if self.links.len() != self.slots() {
            return Err(format!(
                "links has {} entries, resolution {:?} needs {}",
                self.links.len(),
                self.res,
                self.slots()
            ));
        }
        if self.sh.len() != self.density.len() * SH_DIM {
            return Err(format!(
                "{} SH values for {} vertices (need {} each)",
                self.sh.len(),
                self.density.len(),
                SH_DIM
            ));
        }
        let n = self.density.len() as i64;
        if let Some(bad) = self.links.iter().find(|&&l| l as i64 >= n) {
            return Err(format!("link {bad} points past the {n} allocated vertices"));
        }
        // Each vertex has one slot: the kernels (TV's gather) add to a vertex's gradient from its
        // slot alone.
        let mut seen = vec![false; self.density.len()];
        for &l in &self.links {
            if l >= 0 && std::mem::replace(&mut seen[l as usize], true) {
                return Err(format!("links: row {l} is used by two vertices"));
            }
        }
        if self.radius.iter().any(|&r| !(r.is_finite() && r > 0.0))
            || self.center.iter().any(|c| !c.is_finite())
        {
            return Err(format!(
                "centre {:?} / radius {:?} not finite and positive",
                self.center, self.radius
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `InitialFill::Box` allocates every vertex, `Sphere` those inside the inscribed sphere
    /// (π/6 of a fine grid): the shares the memory estimate takes.
    #[test]
    fn initial_fill_allocates_the_box_or_its_inscribed_sphere() {
        for (fill, res) in [(InitialFill::Box, 24), (InitialFill::Sphere, 48)] {
            let g = Grid::sphere(res, [0.5, -1.0, 2.0], [3.0; 3], fill.radius(), 0.1);
            let share = g.density.len() as f64 / (res as f64).powi(3);
            assert!(
                (share - fill.share()).abs() < 0.01,
                "{fill:?}: share {share}"
            );
            assert!(g.density.iter().all(|&s| s == 0.1) && g.sh.iter().all(|&c| c == 0.0));
        }
    }

    #[test]
    fn a_training_grid_is_its_links_and_three_floats_per_parameter() {
        // 2·3·4 slots of 4-byte links; 5 rows of 28 parameters, each value, average, gradient.
        assert_eq!(
            Grid::training_bytes([2, 3, 4], 5),
            (4 * 24 + 5 * 28 * 3 * 4) as f64
        );
        assert_eq!(Grid::training_bytes([8; 3], 0), 4.0 * 512.0);
    }

    #[test]
    fn world_grid_roundtrip_and_box_corners() {
        let g = Grid::sphere(64, [0.1, -0.2, 0.0], [1.0, 1.0, 1.5], 1.0, 0.1);
        let p = [0.3, 0.4, -0.5];
        let back = g.grid_to_world(g.world_to_grid(p));
        for i in 0..3 {
            assert!((back[i] - p[i]).abs() < 1e-5);
        }
        // The box face c − r maps to −0.5, c + r to N − 0.5.
        let lo = g.world_to_grid([0.1 - 1.0, -0.2 - 1.0, -1.5]);
        assert!(lo.iter().all(|&x| (x + 0.5).abs() < 1e-5), "{lo:?}");
    }

    #[test]
    fn sphere_init_and_retain() {
        let mut g = Grid::sphere(16, [0.0; 3], [1.0; 3], 1.0, 0.1);
        let n = g.allocated();
        // Sphere volume fraction π/6 of the box, roughly.
        let frac = n as f64 / g.slots() as f64;
        assert!((frac - std::f64::consts::PI / 6.0).abs() < 0.08, "{frac}");
        assert!(g.validate().is_ok());
        let keep: Vec<bool> = (0..g.slots()).map(|s| g.vertex(s)[0] < 8).collect();
        g.retain(&keep);
        assert!(g.validate().is_ok());
        assert!(g.allocated() < n && g.allocated() > 0);
        for (s, &kept) in keep.iter().enumerate() {
            assert_eq!(
                g.links[s] >= 0,
                kept && g.vertex(s)[0] < 8 && g.links[s] >= 0
            );
        }
    }

    #[test]
    fn a_row_named_by_two_slots_is_refused() {
        let mut g = Grid::sphere(8, [0.0; 3], [1.0; 3], 1.0, 0.1);
        let (a, b) = {
            let mut linked = (0..g.slots()).filter(|&s| g.links[s] >= 0);
            (linked.next().unwrap(), linked.next().unwrap())
        };
        g.links[b] = g.links[a];
        let err = g.validate().unwrap_err();
        assert!(err.contains("used by two vertices"), "{err}");
    }
}
