//! Twin of `glsl/surface_opacity_reg.comp`: Lα (method.md §3.4) over a chunk of the vertex rows.

use crate::abi::regularisers::OpacityChunk;

/// Lα = λ·Σ log σα over the chunk's rows with σα > 0; grad += λ/max(σα, 1e-8) there. Nothing is
/// flagged: RMSProp updates σα on every row of the chunk (`SurfaceRmsProp::opacity_rows`).
/// Returns Lα (f64 sum of the f32 terms λ·ln σα).
pub fn surface_opacity_reg(opacity: &[f32], grad: &mut [f32], c: &OpacityChunk) -> f64 {
    let rows = c.rows as usize;
    if rows == 0 {
        return 0.0;
    }
    let n = (c.count as usize).min(rows);
    let start = c.start as usize % rows;
    let mut loss = 0.0f64;
    for i in 0..n {
        let r = (start + i) % rows;
        let a = opacity[r];
        if a > 0.0 {
            loss += (c.lambda * a.ln()) as f64;
            grad[r] += c.lambda / a.max(1e-8);
        }
    }
    loss
}
