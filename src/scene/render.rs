//! The exact CPU ray caster of the procedural scenes. Per pixel, `spp_side`² rays through a
//! regular sub-pixel lattice (box filter); per ray every surface crossing of the candidate
//! objects is found analytically, sorted by distance and alpha-composited front to back (no
//! refraction) until an opaque hit. The pixel stores the straight (un-premultiplied) colour and
//! the accumulated coverage as alpha. Candidates come from 16×16-pixel screen tiles overlapped by
//! the objects' projected bounding boxes. Rows are rendered in parallel (rayon); the result does
//! not depend on the thread count.

use super::Scene;
use crate::data::Camera;
use glam::{DMat4, DVec3, DVec4};
use rayon::prelude::*;

const TILE: u32 = 16;

/// Colour (premultiplied) and coverage of one ray.
pub fn trace(
    scene: &Scene,
    candidates: &[u32],
    o: DVec3,
    d: DVec3,
    hits: &mut Vec<(f64, u32, DVec3)>,
) -> (DVec3, f64) {
    hits.clear();
    let mut buf = Vec::with_capacity(4);
    for &i in candidates {
        buf.clear();
        scene.objects[i as usize]
            .shape
            .crossings(o, d, 1e-6, &mut buf);
        hits.extend(buf.iter().map(|c| (c.t, i, c.n)));
    }
    hits.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let mut c = DVec3::ZERO;
    let mut trans = 1.0;
    for &(t, i, n) in hits.iter() {
        let ob = &scene.objects[i as usize];
        let a = ob.material.alpha;
        c += trans * a * ob.material.shade(o + t * d, n, d, scene.light);
        trans *= 1.0 - a;
        if trans <= 0.0 {
            break;
        }
    }
    (c, 1.0 - trans)
}

/// Per tile, the objects whose projected bounds overlap it.
fn tile_lists(scene: &Scene, cam: &Camera) -> (u32, Vec<Vec<u32>>) {
    let tx = cam.width.div_ceil(TILE);
    let ty = cam.height.div_ceil(TILE);
    let mut lists = vec![Vec::new(); (tx * ty) as usize];
    let w2c: DMat4 = cam.c2w.as_dmat4().inverse();
    let (fx, fy, cx, cy) = (cam.fx as f64, cam.fy as f64, cam.cx as f64, cam.cy as f64);
    for (i, ob) in scene.objects.iter().enumerate() {
        let mut mark = vec![false; lists.len()];
        for corners in ob.shape.bound_boxes() {
            let mut rect = Some((f64::MAX, f64::MAX, f64::MIN, f64::MIN));
            for p in corners {
                let q = w2c * DVec4::new(p.x, p.y, p.z, 1.0);
                let depth = -q.z;
                if depth <= 1e-4 {
                    rect = None; // straddles the camera plane: every tile
                    break;
                }
                let (px, py) = (cx + fx * q.x / depth, cy - fy * q.y / depth);
                rect = rect.map(|(a, b, c, d)| (a.min(px), b.min(py), c.max(px), d.max(py)));
            }
            let (x0, y0, x1, y1) = match rect {
                Some((a, b, c, d)) => (
                    ((a - 1.0) / TILE as f64).floor(),
                    ((b - 1.0) / TILE as f64).floor(),
                    ((c + 1.0) / TILE as f64).floor(),
                    ((d + 1.0) / TILE as f64).floor(),
                ),
                None => (0.0, 0.0, tx as f64, ty as f64),
            };
            let clampx = |v: f64| v.clamp(0.0, tx as f64 - 1.0) as u32;
            let clampy = |v: f64| v.clamp(0.0, ty as f64 - 1.0) as u32;
            if x1 < 0.0 || y1 < 0.0 || x0 >= tx as f64 || y0 >= ty as f64 {
                continue;
            }
            for y in clampy(y0)..=clampy(y1) {
                for x in clampx(x0)..=clampx(x1) {
                    mark[(y * tx + x) as usize] = true;
                }
            }
        }
        for (l, m) in lists.iter_mut().zip(mark) {
            if m {
                l.push(i as u32);
            }
        }
    }
    (tx, lists)
}

/// Renders one view: RGBA8, straight alpha, row-major, top row first. `spp_side`² samples per
/// pixel on a regular lattice.
pub fn render_view(scene: &Scene, cam: &Camera, spp_side: u32) -> Vec<u8> {
    let (w, h) = (cam.width, cam.height);
    let (tx, lists) = tile_lists(scene, cam);
    let n = spp_side.max(1);
    let inv_n = 1.0 / n as f32;
    let mut out = vec![0u8; (w * h * 4) as usize];
    out.par_chunks_mut((w * 4) as usize)
        .enumerate()
        .for_each(|(y, row)| {
            let y = y as u32;
            let mut hits = Vec::new();
            for x in 0..w {
                let cand = &lists[((y / TILE) * tx + x / TILE) as usize];
                if cand.is_empty() {
                    continue;
                }
                let mut c = DVec3::ZERO;
                let mut a = 0.0;
                for j in 0..n {
                    for i in 0..n {
                        let px = x as f32 + (i as f32 + 0.5) * inv_n;
                        let py = y as f32 + (j as f32 + 0.5) * inv_n;
                        let (o, d) = cam.ray_at(px, py);
                        let (cs, al) = trace(
                            scene,
                            cand,
                            o.as_dvec3(),
                            d.as_dvec3().normalize(),
                            &mut hits,
                        );
                        c += cs;
                        a += al;
                    }
                }
                let s = 1.0 / (n * n) as f64;
                let (c, a) = (c * s, a * s);
                let a8 = (a * 255.0).round().clamp(0.0, 255.0) as u8;
                if a8 == 0 {
                    continue;
                }
                let straight = c / a;
                let px = &mut row[(x * 4) as usize..(x * 4 + 4) as usize];
                for k in 0..3 {
                    px[k] = (straight[k] * 255.0).round().clamp(0.0, 255.0) as u8;
                }
                px[3] = a8;
            }
        });
    out
}
