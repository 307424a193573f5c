//! Point-cloud extraction from a level-set field (method.md §4), host side: list the cells whose 8
//! corners are allocated, run `glsl/extract_points.comp` (or its CPU twin) over them, sort the
//! points by their (cell, level, ray) slot so the result does not depend on the atomic order, map
//! them to world (Blender) units with normals, and thin them with radius 0.001 per level, then on
//! the union. Stage 1 (the "Plen (σ = τ)" baseline) passes the density as the field and no
//! opacity; stage 2 passes δ, its levels, and σα with the `--min-alpha` threshold.

use super::thin::thin_levels;
use crate::abi::extract::{ExtractInput, ExtractPoint};
use crate::cpu::extract_points::extract_points;
use crate::data::ndc::Ndc;
use crate::eval::hidden::Viewpoint;
use crate::gpu::Gpu;
use crate::grid::slot_vertex;
use crate::io::{Extra, ExtraValues, PointCloud};
use crate::kernels::extract_points::{Push, INFO};
use anyhow::{ensure, Result};
use rayon::prelude::*;
use std::time::Instant;

/// Where the extraction kernel runs.
#[derive(Clone, Copy)]
pub enum ExtractBackend<'a> {
    /// `glsl/extract_points.comp` on this device.
    Vulkan(&'a Gpu),
    /// The CPU twin.
    Cpu,
}

/// Kernel-run statistics.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct KernelStats {
    /// Cells visited (all 8 corners allocated).
    pub cells: usize,
    /// Points emitted (one per ray and level at most).
    pub points: usize,
    /// Point-buffer capacity of the last run (Vulkan).
    pub capacity: usize,
    /// Runs repeated because the point buffer was full (Vulkan).
    pub retries: u32,
    /// Device time of the kernel over all runs (Vulkan; 0 on the CPU).
    pub device_ms: f64,
    /// Wall time of listing cells + kernel runs + sorting.
    pub wall_ms: f64,
}

/// `links` slot of corner 000 of every cell whose 8 corners are allocated, ascending.
pub fn allocated_cells(res: [u32; 3], links: &[i32]) -> Result<Vec<u32>> {
    let [x, y, z] = res.map(|r| r as usize);
    ensure!(
        links.len() == x * y * z,
        "links has {} slots, resolution {res:?} needs {}",
        links.len(),
        x * y * z
    );
    ensure!(
        links.len() <= u32::MAX as usize,
        "resolution {res:?}: more than 2^32 vertex slots"
    );
    if x < 2 || y < 2 || z < 2 {
        return Ok(Vec::new());
    }
    let slot = |i: usize, j: usize, k: usize| (i * y + j) * z + k;
    Ok((0..x - 1)
        .into_par_iter()
        .flat_map_iter(|i| {
            (0..y - 1).flat_map(move |j| {
                (0..z - 1).filter_map(move |k| {
                    let s = slot(i, j, k);
                    let all = (0..8)
                        .all(|c| links[slot(i + (c >> 2), j + ((c >> 1) & 1), k + (c & 1))] >= 0);
                    all.then_some(s as u32)
                })
            })
        })
        .collect())
}

/// Run the kernel on the device over `inp.cells`, starting with room for `capacity` points and
/// retrying with the exact count when the buffer was too small (counted in `stats.retries`, which
/// the caller reports). Points in atomic order.
pub fn run_gpu(
    gpu: &Gpu,
    inp: &ExtractInput,
    capacity: usize,
    stats: &mut KernelStats,
) -> Result<Vec<ExtractPoint>> {
    let n_threads = 3 * inp.cells.len();
    ensure!(
        n_threads <= u32::MAX as usize,
        "{} cells: too many for one dispatch",
        inp.cells.len()
    );
    if inp.cells.is_empty() || inp.levels.is_empty() {
        return Ok(Vec::new());
    }
    let cells = gpu.upload(inp.cells)?;
    let links = gpu.upload(inp.links)?;
    let field = gpu.upload(inp.field)?;
    let opacity = inp.opacity.map(|o| gpu.upload(o)).transpose()?;
    let levels = gpu.upload(inp.levels)?;
    let counter = gpu.zeros::<u32>(1)?;
    let mut capacity = capacity.max(1);
    loop {
        let points = gpu.zeros::<ExtractPoint>(capacity)?;
        let mut batch = gpu.batch()?;
        batch.fill_zero(&counter);
        batch.dispatch_1d(
            &INFO,
            &Push {
                cells: cells.address(),
                links: links.address(),
                field: field.address(),
                opacity: opacity.as_ref().map_or(0, |b| b.address()),
                levels: levels.address(),
                counter: counter.address(),
                points: points.address(),
                capacity: capacity.min(u32::MAX as usize) as u32,
                n_cells: inp.cells.len() as u32,
                n_levels: inp.levels.len() as u32,
                res_y: inp.res[1],
                res_z: inp.res[2],
                rays_per_axis: inp.rays_per_axis,
                min_opacity: inp.min_opacity,
                ..Default::default()
            },
            n_threads as u32,
        )?;
        let times = batch.submit()?;
        stats.device_ms += times.kernel_ns(INFO.name) * 1e-6;
        let found = counter.download::<u32>()?[0] as usize;
        stats.capacity = capacity;
        if found <= capacity {
            return points.download_range(0, found);
        }
        stats.retries += 1;
        capacity = found;
    }
}

/// Extraction on `backend`, sorted by (cell, level, ray). `capacity` is the device point buffer's
/// initial size (None: min(upper bound, 2²¹)).
pub fn extract_sorted(
    backend: ExtractBackend,
    inp: &ExtractInput,
    capacity: Option<usize>,
) -> Result<(Vec<ExtractPoint>, KernelStats)> {
    let t0 = Instant::now();
    ensure!(inp.rays_per_axis >= 1, "rays per axis must be ≥ 1");
    let r2 = (inp.rays_per_axis as usize).pow(2);
    ensure!(
        3 * r2 <= u32::MAX as usize / 4,
        "rays per axis {} is too large",
        inp.rays_per_axis
    );
    let mut stats = KernelStats {
        cells: inp.cells.len(),
        ..Default::default()
    };
    let mut points = match backend {
        ExtractBackend::Vulkan(gpu) => {
            let bound = inp.cells.len() * 3 * r2 * inp.levels.len();
            let cap = capacity.unwrap_or(bound.min(1 << 21));
            run_gpu(gpu, inp, cap, &mut stats)?
        }
        ExtractBackend::Cpu => extract_points(inp),
    };
    points.par_sort_unstable_by_key(ExtractPoint::key);
    stats.points = points.len();
    stats.wall_ms = t0.elapsed().as_secs_f64() * 1e3;
    Ok((points, stats))
}

/// Geometry of the field's grid: vertices per axis and the grid → scene map.
#[derive(Clone, Copy, Debug)]
pub struct GridFrame {
    pub res: [u32; 3],
    /// Scene-space (scaled world) box centre and half-extent, as in [`crate::grid::Grid`].
    pub center: [f32; 3],
    pub radius: [f32; 3],
    /// Blender → scene scale (the scene box's 2/3 by default); positions are divided by it.
    pub scene_scale: f32,
    /// The NDC space the grid's box lies in (forward-facing captures; then `scene_scale` is 1):
    /// positions and normals are mapped back through it.
    pub ndc: Option<Ndc>,
}

impl GridFrame {
    /// Continuous grid coordinates → Blender units ([`crate::grid::Grid::grid_to_world`], then
    /// undo the scene scale or the NDC map).
    pub fn to_blender(&self, g: [f32; 3]) -> [f32; 3] {
        let w = self.grid().grid_to_world(g);
        match &self.ndc {
            Some(ndc) => ndc.to_world(w),
            None => w.map(|w| w / self.scene_scale),
        }
    }

    /// Blender units → continuous grid coordinates (the inverse of [`GridFrame::to_blender`]; in
    /// NDC a point behind the frame's camera plane maps to infinity, outside every grid).
    pub fn blender_to_grid(&self, p: [f32; 3]) -> [f32; 3] {
        let w = match &self.ndc {
            Some(ndc) => ndc.to_ndc(p).unwrap_or([f32::INFINITY; 3]),
            None => p.map(|x| x * self.scene_scale),
        };
        self.grid().world_to_grid(w)
    }

    /// A camera centre (Blender units) as the hidden-surface trimming looks toward it: its grid
    /// point (w = 1), or in NDC its homogeneous grid point (a camera near the frame's plane lies
    /// at or beyond infinity there).
    pub fn viewpoint(&self, p: [f32; 3]) -> Viewpoint {
        let Some(ndc) = &self.ndc else {
            let g = self.blender_to_grid(p);
            return [g[0], g[1], g[2], 1.0];
        };
        let h = ndc.homogeneous(p);
        let offset = self.grid().world_to_grid([0.0; 3]);
        let g: [f32; 3] = std::array::from_fn(|i| {
            let scale = self.res[i] as f64 / (2.0 * self.radius[i] as f64);
            (h[i] * scale + h[3] * offset[i] as f64) as f32
        });
        [g[0], g[1], g[2], h[3] as f32]
    }

    /// An empty grid over the frame's box (for its coordinate maps).
    fn grid(&self) -> crate::grid::Grid {
        crate::grid::Grid {
            res: self.res,
            center: self.center,
            radius: self.radius,
            links: Vec::new(),
            density: Vec::new(),
            sh: Vec::new(),
        }
    }

    /// A gradient with respect to grid coordinates at grid point `g` → unit normal in world
    /// units (0 when the gradient is 0). The chain rule scales axis i by N_i / (2 r_i), then
    /// (NDC) through the map's Jacobian; the scene scale is uniform.
    pub fn normal(&self, g: [f32; 3], grad: [f32; 3]) -> [f32; 3] {
        let mut w: [f64; 3] = std::array::from_fn(|i| {
            grad[i] as f64 * self.res[i] as f64 / (2.0 * self.radius[i] as f64)
        });
        if let Some(ndc) = &self.ndc {
            w = ndc.gradient_to_world(self.grid().grid_to_world(g), w);
        }
        let n = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
        if n > 0.0 && n.is_finite() {
            w.map(|x| (x / n) as f32)
        } else {
            [0.0; 3]
        }
    }

    /// A world direction `v` at grid point `g` → the grid direction it moves along (not unit):
    /// the scene scale (or, in NDC, the map's Jacobian), then N_i / (2 r_i) per axis.
    pub fn direction_to_grid(&self, g: [f32; 3], v: [f32; 3]) -> [f32; 3] {
        let w = match &self.ndc {
            Some(ndc) => ndc.direction_to_ndc(self.grid().grid_to_world(g), v),
            None => v.map(|x| x * self.scene_scale),
        };
        std::array::from_fn(|i| w[i] * self.res[i] as f32 / (2.0 * self.radius[i]))
    }
}

/// Counts and timings of [`to_cloud`].
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct ThinStats {
    /// Points per level after the per-level thinning and the union thinning.
    pub per_level: Vec<usize>,
    pub kept: usize,
    pub wall_ms: f64,
}

/// Grid coordinates of an extracted point on a grid of `res` vertices: its cell's corner 000
/// plus its position inside the cell.
pub fn grid_position(res: [u32; 3], p: &ExtractPoint) -> [f32; 3] {
    let v = slot_vertex(res, p.cell as usize);
    std::array::from_fn(|i| v[i] as f32 + p.local[i])
}

/// Sorted kernel points → PLY cloud in Blender units: x, y, z, level (τ), alpha, nx, ny, nz.
/// Normals are ∇field / |∇field|, pointing toward increasing field value (into the object for a
/// density or δ that grows inward). Thinned with `radius` (Blender units) per level, then on the
/// union; `radius ≤ 0` keeps every point.
pub fn to_cloud(
    points: &[ExtractPoint],
    levels: &[f32],
    frame: &GridFrame,
    radius: f64,
) -> Result<(PointCloud, ThinStats)> {
    let t0 = Instant::now();
    let xyz: Vec<[f32; 3]> = points
        .par_iter()
        .map(|p| frame.to_blender(grid_position(frame.res, p)))
        .collect();
    let level_idx: Vec<u32> = points.iter().map(|p| p.level).collect();
    let kept = thin_levels(&xyz, &level_idx, levels.len(), radius)?;
    let mut per_level = vec![0usize; levels.len()];
    let mut cloud = PointCloud {
        points: Vec::with_capacity(kept.len()),
        extras: Vec::new(),
    };
    let (mut lv, mut al, mut nx, mut ny, mut nz) = (vec![], vec![], vec![], vec![], vec![]);
    for &i in &kept {
        let p = &points[i];
        per_level[p.level as usize] += 1;
        cloud.points.push(xyz[i]);
        lv.push(levels[p.level as usize]);
        al.push(p.alpha);
        let n = frame.normal(grid_position(frame.res, p), p.grad);
        nx.push(n[0]);
        ny.push(n[1]);
        nz.push(n[2]);
    }
    for (name, v) in [
        ("level", lv),
        ("alpha", al),
        ("nx", nx),
        ("ny", ny),
        ("nz", nz),
    ] {
        cloud.extras.push(Extra {
            name: name.into(),
            values: ExtraValues::Float(v),
        });
    }
    let stats = ThinStats {
        per_level,
        kept: kept.len(),
        wall_ms: t0.elapsed().as_secs_f64() * 1e3,
    };
    Ok((cloud, stats))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::camera::{look_at, Camera};
    use glam::Vec3;

    /// From any cell, the line toward a camera's viewpoint starts along the grid image of the
    /// world segment from the cell's centre to the camera (box and NDC grids; cameras in front
    /// of, on and behind the NDC frame's plane).
    #[test]
    fn viewpoints_lie_along_the_segment_to_the_camera() {
        let cams: Vec<Camera> = (0..9)
            .map(|i| {
                let eye = Vec3::new((i % 3) as f32 - 1.0, -3.0 + 0.3 * (i / 3) as f32, 0.2);
                Camera::from_angle_x(look_at(eye, Vec3::ZERO, Vec3::Z), 64, 48, 0.8)
            })
            .collect();
        let ndc = Ndc::fit(&cams, 1.5);
        let base = GridFrame {
            res: [64; 3],
            center: [0.0; 3],
            radius: [1.0; 3],
            scene_scale: 2.0 / 3.0,
            ndc: None,
        };
        for frame in [
            base,
            GridFrame {
                scene_scale: 1.0,
                ndc: Some(ndc),
                ..base
            },
        ] {
            for c in &cams {
                let cam = c.centre().to_array();
                let v = frame.viewpoint(cam);
                for cell in [[32.5f32, 20.5, 40.5], [10.5, 50.5, 30.5], [60.5, 5.5, 33.5]] {
                    let p = frame.to_blender(cell);
                    let toward: [f32; 3] = std::array::from_fn(|i| p[i] + 1e-3 * (cam[i] - p[i]));
                    let g = frame.blender_to_grid(toward);
                    let seg: [f32; 3] = std::array::from_fn(|i| g[i] - cell[i]);
                    let dir: [f32; 3] = std::array::from_fn(|i| v[i] - v[3] * cell[i]);
                    let dot: f32 = (0..3).map(|i| seg[i] * dir[i]).sum();
                    let norm = |a: [f32; 3]| a.iter().map(|x| x * x).sum::<f32>().sqrt();
                    let cos = dot / (norm(seg) * norm(dir));
                    assert!(
                        cos > 0.999,
                        "ndc {}: cell {cell:?}, camera {cam:?}: cos {cos}",
                        frame.ndc.is_some()
                    );
                }
            }
        }
    }
}
