//! Twin of `glsl/cubic_solve.comp`: crossings of one (cell, ray, level) case per element.

use crate::math::cubic::{crossings, Crossings};
use rayon::prelude::*;

/// One case, laid out as the kernel reads it (16 floats).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct CubicCase {
    /// δ at the 8 corners, paper order (index 4a + 2b + c; a = x bit, b = y bit, c = z bit).
    pub corners: [f32; 8],
    /// Entry point o′ ∈ [0,1]³ in cell coordinates.
    pub o: [f32; 3],
    /// Unit direction in voxel units.
    pub d: [f32; 3],
    /// Segment length L inside the cell.
    pub l: f32,
    /// Level τ.
    pub tau: f32,
}

impl CubicCase {
    /// The crossings of this case with the f32 solver.
    pub fn solve(&self) -> Crossings {
        crossings(&self.corners, self.o, self.d, self.l, self.tau)
    }
}

/// Kernel outputs, as downloaded: per case a count, and 3 slots of (s, rising ∈ {0, 1}).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CubicSolveOut {
    pub count: Vec<u32>,
    pub s: Vec<f32>,
    pub rising: Vec<u32>,
}

impl CubicSolveOut {
    /// Crossings of case `i`.
    pub fn get(&self, i: usize) -> Crossings {
        let mut x = Crossings {
            n: self.count[i].min(3),
            ..Default::default()
        };
        for k in 0..3 {
            x.s[k] = self.s[3 * i + k];
            x.rising[k] = self.rising[3 * i + k] != 0;
        }
        x
    }
}

/// Solve every case (rayon), writing the kernel's outputs.
pub fn cubic_solve(cases: &[CubicCase]) -> CubicSolveOut {
    let solved: Vec<Crossings> = cases.par_iter().map(CubicCase::solve).collect();
    flatten(&solved)
}

/// Solve every case on the calling thread (for single-thread throughput).
pub fn cubic_solve_serial(cases: &[CubicCase]) -> CubicSolveOut {
    let solved: Vec<Crossings> = cases.iter().map(CubicCase::solve).collect();
    flatten(&solved)
}

fn flatten(solved: &[Crossings]) -> CubicSolveOut {
    let n = solved.len();
    let mut out = CubicSolveOut {
        count: Vec::with_capacity(n),
        s: vec![0.0; 3 * n],
        rising: vec![0; 3 * n],
    };
    for (i, x) in solved.iter().enumerate() {
        out.count.push(x.n);
        for k in 0..x.n as usize {
            out.s[3 * i + k] = x.s[k];
            out.rising[3 * i + k] = x.rising[k] as u32;
        }
    }
    out
}
