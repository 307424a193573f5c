//! Triangle meshes of the level sets: marching tetrahedra on the trilinear field of a sparse grid
//! ([`tetra`]), the mapping to world (Blender) units, area-uniform point sampling (to compare a
//! mesh with a point cloud by Chamfer distance) and binary PLY with faces ([`ply`]). The mesh
//! runs on the CPU (rayon) for every backend: it is a host-side post-process of a trained grid,
//! like the thinning of the point extraction.

pub mod ply;
pub mod tetra;

use crate::eval::extract::GridFrame;
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

pub use tetra::{march, MeshInput};

/// An indexed triangle mesh with per-vertex normals, level τ and opacity α.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub positions: Vec<[f32; 3]>,
    /// Unit normals toward increasing field (0 where the gradient is 0); before
    /// [`Mesh::to_blender`], the raw gradient in grid coordinates.
    pub normals: Vec<[f32; 3]>,
    /// The level τ of the surface the vertex lies on.
    pub level: Vec<f32>,
    /// 1 − exp(−max(σα, 0)) at the vertex; 1 for a field without opacity.
    pub alpha: Vec<f32>,
    /// 8-bit RGB surface colour per vertex ([`crate::eval::colour`]); empty for an uncoloured
    /// mesh.
    pub colour: Vec<[u8; 3]>,
    /// Counter-clockwise seen from the side the normals point to.
    pub faces: Vec<[u32; 3]>,
}

impl Mesh {
    /// Grid coordinates → Blender units, gradients → unit normals (as the point extraction maps
    /// its points, [`GridFrame`]).
    pub fn to_blender(mut self, frame: &GridFrame) -> Mesh {
        self.normals
            .par_iter_mut()
            .zip(&self.positions)
            .for_each(|(n, p)| *n = frame.normal(*p, *n));
        self.positions
            .par_iter_mut()
            .for_each(|p| *p = frame.to_blender(*p));
        self
    }

    /// Keep the faces for which `keep` holds (by index), and the vertices they use.
    pub fn retain_faces(&mut self, keep: impl Fn(usize) -> bool) {
        self.faces = (0..self.faces.len())
            .filter(|&i| keep(i))
            .map(|i| self.faces[i])
            .collect();
        let mut new_index = vec![u32::MAX; self.positions.len()];
        let mut next = 0u32;
        for f in &mut self.faces {
            for v in f.iter_mut() {
                if new_index[*v as usize] == u32::MAX {
                    new_index[*v as usize] = next;
                    next += 1;
                }
                *v = new_index[*v as usize];
            }
        }
        let mut order: Vec<(u32, usize)> = new_index
            .iter()
            .enumerate()
            .filter(|(_, &n)| n != u32::MAX)
            .map(|(old, &n)| (n, old))
            .collect();
        order.sort_unstable();
        let pick = |v: &[f32]| order.iter().map(|&(_, o)| v[o]).collect::<Vec<f32>>();
        self.positions = order.iter().map(|&(_, o)| self.positions[o]).collect();
        self.normals = order.iter().map(|&(_, o)| self.normals[o]).collect();
        self.level = pick(&self.level);
        self.alpha = pick(&self.alpha);
        if !self.colour.is_empty() {
            self.colour = order.iter().map(|&(_, o)| self.colour[o]).collect();
        }
    }

    /// Area of each face.
    pub fn face_areas(&self) -> Vec<f64> {
        self.faces
            .par_iter()
            .map(|f| {
                let [a, b, c] = f.map(|i| self.positions[i as usize].map(f64::from));
                let (u, v) = (sub(b, a), sub(c, a));
                let n = [
                    u[1] * v[2] - u[2] * v[1],
                    u[2] * v[0] - u[0] * v[2],
                    u[0] * v[1] - u[1] * v[0],
                ];
                0.5 * (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt()
            })
            .collect()
    }

    /// `n` points uniformly distributed over the surface by area (a face drawn with probability
    /// ∝ its area, then a uniform point in it), reproducible from `seed`. Empty for a mesh
    /// without area.
    pub fn sample(&self, n: usize, seed: u64) -> Vec<[f32; 3]> {
        let areas = self.face_areas();
        let mut cdf = Vec::with_capacity(areas.len());
        let mut total = 0.0;
        for a in &areas {
            total += a;
            cdf.push(total);
        }
        let has_area = total > 0.0;
        if !has_area {
            return Vec::new();
        }
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        (0..n)
            .map(|_| {
                let r = rng.random::<f64>() * total;
                let fi = cdf.partition_point(|&c| c <= r).min(cdf.len() - 1);
                let [a, b, c] = self.faces[fi].map(|i| self.positions[i as usize].map(f64::from));
                // Uniform in the triangle: folding the unit square onto it.
                let (mut s, mut t) = (rng.random::<f64>(), rng.random::<f64>());
                if s + t > 1.0 {
                    (s, t) = (1.0 - s, 1.0 - t);
                }
                std::array::from_fn(|i| (a[i] + s * (b[i] - a[i]) + t * (c[i] - a[i])) as f32)
            })
            .collect()
    }
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| a[i] - b[i])
}

/// Counts and timings of [`level_set_mesh`].
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct MeshStats {
    pub vertices: usize,
    pub faces: usize,
    /// Faces per level.
    pub per_level: Vec<usize>,
    /// Total area, Blender units².
    pub area: f64,
    pub wall_ms: f64,
}

/// The level-set mesh of `inp` in Blender units ([`march`], then [`Mesh::to_blender`]).
pub fn level_set_mesh(inp: &MeshInput, frame: &GridFrame) -> anyhow::Result<(Mesh, MeshStats)> {
    let t0 = std::time::Instant::now();
    let mesh = march(inp)?.to_blender(frame);
    let stats = MeshStats::of(&mesh, inp.levels, t0.elapsed().as_secs_f64() * 1e3);
    Ok((mesh, stats))
}

impl MeshStats {
    /// The counts and area of `mesh` with levels `levels`, made in `wall_ms`.
    pub fn of(mesh: &Mesh, levels: &[f32], wall_ms: f64) -> MeshStats {
        let mut per_level = vec![0usize; levels.len()];
        for f in &mesh.faces {
            let l = mesh.level[f[0] as usize];
            if let Some(i) = levels.iter().position(|&x| x == l) {
                per_level[i] += 1;
            }
        }
        MeshStats {
            vertices: mesh.positions.len(),
            faces: mesh.faces.len(),
            per_level,
            area: mesh.face_areas().iter().sum(),
            wall_ms,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn retained_faces_keep_their_vertices_in_order() {
        let mut m = Mesh {
            positions: (0..5).map(|i| [i as f32, 0.0, 0.0]).collect(),
            normals: (0..5).map(|i| [0.0, i as f32, 0.0]).collect(),
            level: vec![0.0, 1.0, 2.0, 3.0, 4.0],
            alpha: vec![0.5, 0.6, 0.7, 0.8, 0.9],
            colour: (0..5).map(|i| [i as u8; 3]).collect(),
            faces: vec![[0, 1, 2], [2, 3, 4], [4, 1, 3]],
        };
        m.retain_faces(|i| i != 0);
        assert_eq!(m.faces, vec![[0, 1, 2], [2, 3, 1]]);
        assert_eq!(
            m.positions,
            vec![
                [2.0, 0.0, 0.0],
                [3.0, 0.0, 0.0],
                [4.0, 0.0, 0.0],
                [1.0, 0.0, 0.0]
            ]
        );
        assert_eq!(m.normals[3], [0.0, 1.0, 0.0]);
        assert_eq!(m.level, vec![2.0, 3.0, 4.0, 1.0]);
        assert_eq!(m.alpha, vec![0.7, 0.8, 0.9, 0.6]);
        assert_eq!(m.colour, vec![[2; 3], [3; 3], [4; 3], [1; 3]]);
        m.retain_faces(|_| false);
        assert!(m.faces.is_empty() && m.positions.is_empty() && m.alpha.is_empty());
    }

    #[test]
    fn samples_are_uniform_by_area_and_reproducible() {
        // Two triangles in the plane z = 0: area 2 (x in [0, 2]) and area 0.5 (x in [3, 4]).
        let m = Mesh {
            positions: vec![
                [0.0, 0.0, 0.0],
                [2.0, 0.0, 0.0],
                [0.0, 2.0, 0.0],
                [3.0, 0.0, 0.0],
                [4.0, 0.0, 0.0],
                [3.0, 1.0, 0.0],
            ],
            faces: vec![[0, 1, 2], [3, 4, 5]],
            ..Default::default()
        };
        assert_eq!(m.face_areas(), vec![2.0, 0.5]);
        let s = m.sample(20_000, 7);
        assert_eq!(s, m.sample(20_000, 7));
        let in_first = s.iter().filter(|p| p[0] <= 2.0).count() as f64 / s.len() as f64;
        // Binomial standard deviation √(0.8·0.2/20000) ≈ 0.003: 0.8 ± 0.015 is 5 σ.
        assert!((in_first - 0.8).abs() < 0.015, "{in_first}");
        for p in &s {
            let inside = if p[0] <= 2.0 {
                p[0] >= 0.0 && p[1] >= 0.0 && p[0] + p[1] <= 2.0 + 1e-5
            } else {
                p[1] >= 0.0 && p[1] <= 4.0 - p[0] + 1e-5 && p[0] >= 3.0
            };
            assert!(inside && p[2] == 0.0, "{p:?}");
        }
        // Uniform inside a triangle: the mean is the centroid.
        let first: Vec<_> = s.iter().filter(|p| p[0] <= 2.0).collect();
        let mx = first.iter().map(|p| p[0] as f64).sum::<f64>() / first.len() as f64;
        assert!((mx - 2.0 / 3.0).abs() < 0.02, "{mx}");
        assert!(Mesh::default().sample(10, 0).is_empty());
    }
}
