//! Marching tetrahedra on the trilinear field of a sparse grid. Each cell whose 8 corners are
//! allocated is split into the 6 tetrahedra of its Kuhn triangulation (all sharing the diagonal
//! 000–111), so every tetrahedron edge joins a grid vertex u to u + d with d ∈ {0,1}³ \ {0}: an
//! axis edge, a face diagonal or the cell diagonal. Neighbouring cells split their shared face
//! along the same diagonal, so the surface has no cracks, and an edge is named by (u, d) alone,
//! which welds the vertices: each level-set vertex is computed once per (level, edge).
//!
//! A vertex lies on the trilinear level set itself, not on a linear approximation: the field is
//! linear along an axis edge (closed form) and a quadratic or cubic along a diagonal (bisection
//! between its endpoints, which straddle the level). Corners with value ≥ τ are "above"; where a
//! corner's value is exactly τ, the vertex is that corner, shared by all the edges meeting there
//! (faces that collapse to a line or a point are dropped).
//!
//! Opacity trimming (stage 2) follows the point extraction's rule: a face is kept when the
//! trilerped σα at its centroid is ≥ the threshold; vertices only used by dropped faces are
//! dropped too. Faces are wound so that their normal points toward increasing field, the
//! direction of the per-vertex normals (the field gradient averaged over the cells that use the
//! vertex). Everything is in grid coordinates: [`super::Mesh::to_blender`] maps it to world units.

use super::Mesh;
use crate::math::surface::surf_alpha;
use crate::math::trilerp::{trilerp, trilerp_grad};
use anyhow::{ensure, Result};
use rayon::prelude::*;

/// The fields and levels to mesh (the same arrays the point extraction reads).
#[derive(Clone, Copy, Debug)]
pub struct MeshInput<'a> {
    /// `links` slot of corner 000 of each cell to visit (all 8 corners allocated), ascending.
    pub cells: &'a [u32],
    /// Index volume, X·Y·Z, < 0 empty.
    pub links: &'a [i32],
    /// Scalar field per allocated vertex (σ for stage 1, δ for stage 2).
    pub field: &'a [f32],
    /// Raw opacity σα per allocated vertex, or `None` (no trimming, α = 1).
    pub opacity: Option<&'a [f32]>,
    /// Level values τ.
    pub levels: &'a [f32],
    /// Vertices per axis.
    pub res: [u32; 3],
    /// Keep a face only when the trilerped σα at its centroid ≥ this (ignored without `opacity`).
    pub min_opacity: f32,
}

/// The 6 tetrahedra of the Kuhn split: corners 0, a, a|b, 7 for each ordered pair of axis bits.
const TETS: [[usize; 4]; 6] = [
    [0, 4, 6, 7],
    [0, 4, 5, 7],
    [0, 2, 6, 7],
    [0, 2, 3, 7],
    [0, 1, 5, 7],
    [0, 1, 3, 7],
];

/// Cell-local position of corner k (bit 4 = x, 2 = y, 1 = z, as in `math::trilerp`).
fn corner(k: usize) -> [f32; 3] {
    [(k >> 2) as f32, ((k >> 1) & 1) as f32, (k & 1) as f32]
}

/// One use of a level-set vertex by a kept face of one cell.
#[derive(Clone, Copy)]
struct VertexUse {
    key: u64,
    /// Grid coordinates.
    pos: [f32; 3],
    /// ∂field/∂(grid coordinates) of this cell's trilerp at the vertex.
    grad: [f32; 3],
    /// 1 − exp(−max(σα, 0)) at the vertex; 1 without opacity.
    alpha: f32,
}

/// Where the field of one cell crosses `tau` on the edge from corner `p` to corner `q`
/// (p ⊂ q as corner bit sets, `c[p]` and `c[q]` on opposite sides): cell-local position.
fn crossing(c: &[f32; 8], p: usize, q: usize, tau: f32) -> [f32; 3] {
    let (a, b) = (corner(p), corner(q));
    let at = |t: f32| std::array::from_fn::<f32, 3, _>(|i| a[i] + t * (b[i] - a[i]));
    let (g0, g1) = (c[p] - tau, c[q] - tau);
    if (p ^ q).count_ones() == 1 {
        // Linear along an axis edge.
        let t = if g0 == g1 { 0.5 } else { g0 / (g0 - g1) };
        return at(t.clamp(0.0, 1.0));
    }
    // Along a diagonal the trilerp is a quadratic or cubic in t: bisect the sign change.
    let above0 = g0 >= 0.0;
    let (mut lo, mut hi) = (0.0f32, 1.0f32);
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if (trilerp(c, at(mid)) - tau >= 0.0) == above0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    at(0.5 * (lo + hi))
}

/// Name of the edge from cell corner `p` to `q` (p ⊂ q) of the cell at `cell` for level `l`:
/// (level, slot of the grid vertex at corner p, direction bits q ^ p). With p = q (direction 0)
/// it names the grid vertex itself, for a level-set vertex that lies exactly on it.
fn edge_key(l: usize, cell: u32, p: usize, q: usize, res: [u32; 3]) -> u64 {
    let yz = res[1] as u64 * res[2] as u64;
    let slot =
        cell as u64 + (p >> 2) as u64 * yz + ((p >> 1) & 1) as u64 * res[2] as u64 + (p & 1) as u64;
    ((l as u64 * yz * res[0] as u64 + slot) << 3) | (p ^ q) as u64
}

/// Vertex coordinates of a `links` slot.
fn slot_xyz(slot: u32, res: [u32; 3]) -> [f32; 3] {
    crate::grid::slot_vertex(res, slot as usize).map(|v| v as f32)
}

/// Faces (as vertex keys) and vertex uses of one cell.
fn cell_faces(inp: &MeshInput, cell: u32, faces: &mut Vec<[u64; 3]>, uses: &mut Vec<VertexUse>) {
    let yz = inp.res[1] * inp.res[2];
    let mut c = [0f32; 8];
    let mut a = [0f32; 8];
    for k in 0..8u32 {
        let slot = cell + (k >> 2) * yz + ((k >> 1) & 1) * inp.res[2] + (k & 1);
        let row = inp.links[slot as usize] as usize;
        c[k as usize] = inp.field[row];
        if let Some(op) = inp.opacity {
            a[k as usize] = op[row];
        }
    }
    let cmin = c.iter().copied().fold(f32::MAX, f32::min);
    let cmax = c.iter().copied().fold(-f32::MAX, f32::max);
    let origin = slot_xyz(cell, inp.res);
    let first_use = uses.len();
    for (l, &tau) in inp.levels.iter().enumerate() {
        if !(cmin <= tau && tau <= cmax) {
            continue;
        }
        for tet in &TETS {
            let above: Vec<usize> = tet.iter().copied().filter(|&k| c[k] >= tau).collect();
            let below: Vec<usize> = tet.iter().copied().filter(|&k| c[k] < tau).collect();
            if above.is_empty() || below.is_empty() {
                continue;
            }
            // The crossing edges as a cycle around the cut: a triangle (1–3 split) or a quad.
            let ring: Vec<(usize, usize)> = match (above.len(), below.len()) {
                (1, _) => below.iter().map(|&b| (above[0], b)).collect(),
                (_, 1) => above.iter().map(|&u| (u, below[0])).collect(),
                _ => vec![
                    (above[0], below[0]),
                    (above[0], below[1]),
                    (above[1], below[1]),
                    (above[1], below[0]),
                ],
            };
            let verts: Vec<(u64, [f32; 3])> = ring
                .iter()
                .map(|&(u, b)| {
                    if c[u] == tau {
                        // On the corner itself: one vertex for every edge that meets there.
                        (edge_key(l, cell, u, u, inp.res), corner(u))
                    } else {
                        let (p, q) = (u.min(b), u.max(b));
                        (edge_key(l, cell, p, q, inp.res), crossing(&c, p, q, tau))
                    }
                })
                .collect();
            // From the below side toward the above side.
            let mean = |ks: &[usize]| -> [f32; 3] {
                let mut m = [0f32; 3];
                for &k in ks {
                    let p = corner(k);
                    (0..3).for_each(|i| m[i] += p[i] / ks.len() as f32);
                }
                m
            };
            let (ma, mb) = (mean(&above), mean(&below));
            let up: [f32; 3] = std::array::from_fn(|i| ma[i] - mb[i]);
            for tri in [[0, 1, 2], [0, 2, 3]].iter().take(verts.len() - 2) {
                let [v0, v1, v2] = tri.map(|i| verts[i]);
                let n = cross(sub(v1.1, v0.1), sub(v2.1, v0.1));
                let area2 = dot(n, n);
                let has_area = area2 > 1e-24; // false when degenerate: a corner exactly at τ
                if !has_area {
                    continue;
                }
                let centroid: [f32; 3] =
                    std::array::from_fn(|i| (v0.1[i] + v1.1[i] + v2.1[i]) / 3.0);
                // NaN opacity fails the test, as in the point extraction.
                let opaque = trilerp(&a, centroid) >= inp.min_opacity;
                if inp.opacity.is_some() && !opaque {
                    continue;
                }
                let face = if dot(n, up) >= 0.0 {
                    [v0.0, v1.0, v2.0]
                } else {
                    [v0.0, v2.0, v1.0]
                };
                faces.push(face);
                for (key, local) in [v0, v1, v2] {
                    let alpha = if inp.opacity.is_some() {
                        surf_alpha(trilerp(&a, local))
                    } else {
                        1.0
                    };
                    uses.push(VertexUse {
                        key,
                        pos: std::array::from_fn(|i| origin[i] + local[i]),
                        grad: trilerp_grad(&c, local).1,
                        alpha,
                    });
                }
            }
        }
    }
    // One use per vertex and cell, so that each cell weighs once in the normal.
    uses[first_use..].sort_by_key(|u| u.key);
    let mut w = first_use;
    for r in first_use..uses.len() {
        if w == first_use || uses[w - 1].key != uses[r].key {
            uses[w] = uses[r];
            w += 1;
        }
    }
    uses.truncate(w);
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    std::array::from_fn(|i| a[i] - b[i])
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// The welded level-set mesh of `inp`, in grid coordinates; per-vertex normals are the averaged
/// field gradient with respect to grid coordinates (not normalised). Deterministic: vertices in
/// (level, edge) order, faces in cell order; independent of the thread count.
pub fn march(inp: &MeshInput) -> Result<Mesh> {
    let [x, y, z] = inp.res.map(|r| r as u64);
    ensure!(
        inp.links.len() as u64 == x * y * z,
        "links has {} slots, resolution {:?} needs {}",
        inp.links.len(),
        inp.res,
        x * y * z
    );
    ensure!(
        (inp.levels.len() as u64).saturating_mul(x * y * z) < 1 << 60,
        "{} levels on a {:?} grid: too many edges to name",
        inp.levels.len(),
        inp.res
    );
    let per_cell: Vec<(Vec<[u64; 3]>, Vec<VertexUse>)> = inp
        .cells
        .par_chunks(1024)
        .map(|chunk| {
            let (mut f, mut u) = (Vec::new(), Vec::new());
            for &cell in chunk {
                cell_faces(inp, cell, &mut f, &mut u);
            }
            (f, u)
        })
        .collect();
    let mut uses: Vec<VertexUse> = Vec::new();
    let mut face_keys: Vec<[u64; 3]> = Vec::new();
    for (f, u) in per_cell {
        face_keys.extend(f);
        uses.extend(u);
    }
    // Weld: one vertex per key, position and α from its first cell, gradient averaged over cells.
    uses.par_sort_by_key(|u| u.key); // stable: cell order within a key
    let mut mesh = Mesh::default();
    let mut keys: Vec<u64> = Vec::new();
    let mut i = 0;
    while i < uses.len() {
        let mut j = i;
        let mut g = [0f64; 3];
        while j < uses.len() && uses[j].key == uses[i].key {
            (0..3).for_each(|k| g[k] += uses[j].grad[k] as f64);
            j += 1;
        }
        let n = (j - i) as f64;
        keys.push(uses[i].key);
        mesh.positions.push(uses[i].pos);
        mesh.normals.push(g.map(|v| (v / n) as f32));
        mesh.level
            .push(inp.levels[(uses[i].key >> 3) as usize / (x * y * z) as usize]);
        mesh.alpha.push(uses[i].alpha);
        i = j;
    }
    ensure!(
        mesh.positions.len() <= u32::MAX as usize,
        "{} mesh vertices: more than a u32 index can name",
        mesh.positions.len()
    );
    mesh.faces = face_keys
        .par_iter()
        .map(|f| f.map(|k| keys.binary_search(&k).expect("every face vertex has a use") as u32))
        .collect();
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::extract::allocated_cells;
    use std::collections::HashMap;

    /// A dense n³ grid with `f` at each vertex (grid coordinates), every vertex allocated.
    fn dense(n: u32, f: impl Fn([f32; 3]) -> f32) -> (Vec<i32>, Vec<f32>) {
        let mut links = Vec::new();
        let mut field = Vec::new();
        for i in 0..n {
            for j in 0..n {
                for k in 0..n {
                    links.push(field.len() as i32);
                    field.push(f([i as f32, j as f32, k as f32]));
                }
            }
        }
        (links, field)
    }

    fn sphere_field(c: f32, r: f32) -> impl Fn([f32; 3]) -> f32 {
        move |p| r - ((p[0] - c).powi(2) + (p[1] - c).powi(2) + (p[2] - c).powi(2)).sqrt()
    }

    #[test]
    fn a_sphere_is_a_closed_oriented_welded_surface() {
        let (n, c, r) = (20u32, 9.3f32, 6.1f32);
        let (links, field) = dense(n, sphere_field(c, r));
        let cells = allocated_cells([n; 3], &links).unwrap();
        let inp = MeshInput {
            cells: &cells,
            links: &links,
            field: &field,
            opacity: None,
            levels: &[0.0],
            res: [n; 3],
            min_opacity: 0.0,
        };
        let m = march(&inp).unwrap();
        assert!(m.faces.len() > 1000, "{} faces", m.faces.len());
        // Every directed edge once and its reverse once: closed (no cracks between cells),
        // consistently oriented, and welded (a duplicated vertex would leave open edges).
        let mut directed: HashMap<(u32, u32), u32> = HashMap::new();
        for f in &m.faces {
            for k in 0..3 {
                *directed.entry((f[k], f[(k + 1) % 3])).or_default() += 1;
            }
        }
        for (&(a, b), &count) in &directed {
            assert_eq!(count, 1, "edge {a}→{b} used {count} times");
            assert_eq!(directed.get(&(b, a)), Some(&1), "edge {a}→{b} has no twin");
        }
        // Euler characteristic of a sphere: V − E + F = 2.
        let euler = m.positions.len() as i64 - (directed.len() / 2) as i64 + m.faces.len() as i64;
        assert_eq!(euler, 2);
        // On the surface (the trilerp of a distance field is within a small fraction of a cell
        // of the sphere at this radius), with the area of the sphere.
        for p in &m.positions {
            let d = (p.iter().map(|v| (v - c).powi(2)).sum::<f32>()).sqrt();
            assert!((d - r).abs() < 0.05, "vertex {p:?} at radius {d}");
        }
        let area: f64 = m.face_areas().iter().sum();
        let exact = 4.0 * std::f64::consts::PI * (r as f64).powi(2);
        assert!((area / exact - 1.0).abs() < 0.01, "area {area} vs {exact}");
        // Normals (the gradient) point toward increasing field, into the sphere, and faces are
        // wound the same way.
        for (p, g) in m.positions.iter().zip(&m.normals) {
            let inward: [f32; 3] = std::array::from_fn(|i| c - p[i]);
            assert!(dot(*g, inward) > 0.9 * dot(*g, *g).sqrt() * dot(inward, inward).sqrt());
        }
        for f in &m.faces {
            let [a, b, cc] = f.map(|i| m.positions[i as usize]);
            let n = cross(sub(b, a), sub(cc, a));
            assert!(dot(n, m.normals[f[0] as usize]) > 0.0);
        }
        assert!(m.level.iter().all(|&l| l == 0.0) && m.alpha.iter().all(|&a| a == 1.0));
    }

    #[test]
    fn a_level_through_grid_vertices_welds_there() {
        // f = x + y + z − 12 on integer vertices: the plane passes exactly through grid vertices
        // (value 0 = τ), where every edge meeting the vertex would otherwise make its own copy.
        let n = 10u32;
        let (links, field) = dense(n, |p| p[0] + p[1] + p[2] - 12.0);
        let cells = allocated_cells([n; 3], &links).unwrap();
        let inp = MeshInput {
            cells: &cells,
            links: &links,
            field: &field,
            opacity: None,
            levels: &[0.0],
            res: [n; 3],
            min_opacity: 0.0,
        };
        let m = march(&inp).unwrap();
        assert!(!m.faces.is_empty());
        let mut pos: Vec<[u32; 3]> = m.positions.iter().map(|p| p.map(f32::to_bits)).collect();
        pos.sort_unstable();
        pos.dedup();
        assert_eq!(pos.len(), m.positions.len(), "vertices at the same place");
        for f in &m.faces {
            assert!(f[0] != f[1] && f[1] != f[2] && f[0] != f[2], "{f:?}");
        }
        for p in &m.positions {
            assert!((p[0] + p[1] + p[2] - 12.0).abs() < 1e-5, "{p:?}");
        }
    }

    #[test]
    fn levels_sparsity_and_opacity_trimming() {
        let (n, c) = (16u32, 7.5f32);
        let (mut links, field) = dense(n, sphere_field(c, 10.0));
        // Unallocate one vertex: the 8 cells around it are not meshed.
        let hole = ((8 * n + 8) * n + 2) as usize;
        links[hole] = -1;
        let cells = allocated_cells([n; 3], &links).unwrap();
        // σα = 2 where x < 7, else 0; threshold 1 keeps the faces with centroid x < 7.
        let opacity: Vec<f32> = (0..field.len())
            .map(|row| {
                if ((row as u32) / (n * n)) < 7 {
                    2.0
                } else {
                    0.0
                }
            })
            .collect();
        let levels = [4.0, 6.0];
        let inp = MeshInput {
            cells: &cells,
            links: &links,
            field: &field,
            opacity: Some(&opacity),
            levels: &levels,
            res: [n; 3],
            min_opacity: 1.0,
        };
        let m = march(&inp).unwrap();
        assert!(!m.faces.is_empty());
        for l in levels {
            assert!(m.level.contains(&l), "no vertex at level {l}");
        }
        for f in &m.faces {
            let lv = f.map(|i| m.level[i as usize]);
            assert!(lv[0] == lv[1] && lv[1] == lv[2], "a face across levels");
            let cx = f.iter().map(|&i| m.positions[i as usize][0]).sum::<f32>() / 3.0;
            assert!(cx <= 7.0, "face with centroid x = {cx} kept");
        }
        // α = 1 − exp(−σα) of the trilerped σα at the vertex, in [0, 1].
        assert!(m
            .alpha
            .iter()
            .all(|&a| (0.0..=1.0 - (-2.0f32).exp() + 1e-6).contains(&a)));
        // Every vertex is used, and nothing lies in the cells around the unallocated vertex.
        let mut used = vec![false; m.positions.len()];
        m.faces
            .iter()
            .flatten()
            .for_each(|&i| used[i as usize] = true);
        assert!(used.iter().all(|&u| u));
        for p in &m.positions {
            let inside = (0..3).all(|i| (p[i] - [8.0, 8.0, 2.0][i]).abs() < 1.0);
            assert!(!inside, "vertex {p:?} in a cell with an unallocated corner");
        }
        // No opacity field: more faces (the x ≥ 7 part is back).
        let all = march(&MeshInput {
            opacity: None,
            ..inp
        })
        .unwrap();
        assert!(all.faces.len() > m.faces.len() + 100);
    }
}
