//! GPU-vs-CPU-twin parity checks, one row per kernel. `alphasurf check-kernels` prints them and
//! `tests/kernels/parity.rs` asserts them: the same code decides pass/fail in both places.

use crate::gpu::Gpu;

pub mod background_msi;
pub mod cases;
pub mod cubic_solve;
pub mod dda_walk;
pub mod extract_points;
pub mod fill_pattern;
pub mod loss_sum;
pub mod plenoxel;
pub mod registry;
pub mod sample_rays;
pub mod sh_eval;
pub mod surface_blocks;
pub mod surface_faces;
pub mod surface_fwd;
pub mod surface_reg;
pub mod surface_train;
pub mod trilerp_eval;

pub use registry::rows;

/// The background the parity rows of the render and training kernels composite on: neither
/// white nor grey, so a kernel that ignores its background (or mixes up its channels) fails.
pub const TEST_BACKGROUND: [f32; 3] = [0.2, 0.6, 0.9];

/// Result of comparing one kernel on the Vulkan device with its CPU twin.
#[derive(Debug, Clone, serde::Serialize)]
pub struct CheckRow {
    /// Kernel name (`glsl/<kernel>.comp`).
    pub kernel: &'static str,
    /// Number of cases (inputs) compared.
    pub cases: usize,
    /// Largest absolute difference over compared outputs.
    pub max_abs: f64,
    /// Largest relative difference, |g − c| / max(|c|, tiny).
    pub max_rel: f64,
    /// Tolerance applied, in words (e.g. "abs 1e-6 + rel 1e-5 elementwise").
    pub tolerance: String,
    /// Whether every comparison met the tolerance.
    pub pass: bool,
    /// Extra detail: first mismatch, counts of exact-match discrete outputs, etc.
    pub note: String,
}

/// One kernel's parity check.
pub type CheckFn = fn(&Gpu, u64) -> anyhow::Result<CheckRow>;

/// Relative L2 distance ‖a − b‖/‖b‖ (0 when both vanish, ∞ when only `b` does).
pub fn rel_l2(a: &[f32], b: &[f32]) -> f64 {
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for (&x, &y) in a.iter().zip(b) {
        num += (x as f64 - y as f64).powi(2);
        den += (y as f64).powi(2);
    }
    if den == 0.0 {
        if num == 0.0 {
            0.0
        } else {
            f64::INFINITY
        }
    } else {
        (num / den).sqrt()
    }
}

/// How many elements of `a` are off `b` by more than 1e-4·max|b| + 1e-3·|b| (the gradient checks
/// of both stages allow 0.1 % of them, next to a bound on `rel_l2`).
pub fn grad_outliers(a: &[f32], b: &[f32]) -> usize {
    let scale = b.iter().fold(0f32, |m, &x| m.max(x.abs())) as f64;
    a.iter()
        .zip(b)
        .filter(|(&x, &y)| (x as f64 - y as f64).abs() > 1e-4 * scale + 1e-3 * (y as f64).abs())
        .count()
}

/// Elementwise |a − b| ≤ abs + rel·|b| test with running maxima.
#[derive(Debug, Default, Clone, Copy)]
pub struct Tolerance {
    pub abs: f64,
    pub rel: f64,
}

impl Tolerance {
    pub fn describe(&self) -> String {
        format!("|Δ| ≤ {:.0e} + {:.0e}·|cpu|", self.abs, self.rel)
    }
}

/// Accumulates elementwise comparisons of GPU outputs against CPU-twin outputs.
#[derive(Debug, Default)]
pub struct Compare {
    pub tol: Tolerance,
    pub max_abs: f64,
    pub max_rel: f64,
    pub failures: usize,
    pub compared: usize,
    pub first_failure: Option<String>,
}

impl Compare {
    pub fn new(abs: f64, rel: f64) -> Self {
        Compare {
            tol: Tolerance { abs, rel },
            ..Default::default()
        }
    }

    /// Compare one value; `what` names it in the first-failure note.
    pub fn value(&mut self, gpu: f64, cpu: f64, what: impl FnOnce() -> String) {
        self.compared += 1;
        let d = (gpu - cpu).abs();
        let ok = if gpu.is_nan() || cpu.is_nan() {
            gpu.is_nan() && cpu.is_nan()
        } else if gpu.is_infinite() || cpu.is_infinite() {
            gpu == cpu
        } else {
            self.max_abs = self.max_abs.max(d);
            self.max_rel = self.max_rel.max(d / cpu.abs().max(1e-30));
            d <= self.tol.abs + self.tol.rel * cpu.abs()
        };
        if !ok {
            self.failures += 1;
            if self.first_failure.is_none() {
                self.first_failure = Some(format!("{}: gpu {gpu:e} cpu {cpu:e}", what()));
            }
        }
    }

    /// Turn the comparison into a table row.
    pub fn row(self, kernel: &'static str, cases: usize, note: String) -> CheckRow {
        let mut note = note;
        if let Some(f) = &self.first_failure {
            note = format!("{} failures, first {f}. {note}", self.failures);
        }
        CheckRow {
            kernel,
            cases,
            max_abs: self.max_abs,
            max_rel: self.max_rel,
            tolerance: self.tol.describe(),
            pass: self.failures == 0 && self.compared > 0,
            note,
        }
    }
}
