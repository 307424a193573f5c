//! Structs the kernels read or write in their buffers: the one definition of each layout.
//! `build.rs` reads this file too: it declares each struct in the generated `abi.glsl` (scalar
//! layout, with a `<Name>Buf` buffer reference over an array of it) and fails the build when a
//! kernel's SPIR-V places a member at another offset than this `#[repr(C)]` struct.
//!
//! Member types: `u32`, `i32`, `f32`, `[T; 2..=4]` of those (GLSL `uvec`/`ivec`/`vec`),
//! `[T; N]` for other N (a GLSL array), or a struct declared above. `counters` structs hold `u32`
//! counters only.

use super::consts::SURF_MAX_LEVELS;

abi_structs! {
    /// The params buffer of `surface_fwd` and `surface_train`: how rays map into the grid, the
    /// batch, the levels, truncation, early stop and the loss weights (`surface::vulkan::
    /// surf_params`; the loss weights are zero for a render). Both kernels' push blocks are at
    /// lavapipe's 128-byte limit without these.
    struct SurfParams {
        /// grid = p·scale + offset (per axis).
        scale: [f32; 3],
        offset: [f32; 3],
        /// Truncation parameter a.
        a: f32,
        /// Stop once transmittance falls below this.
        stop_thresh: f32,
        /// dL/dC = grad_scale·(C − target).
        grad_scale: f32,
        /// Weight of the entropy of the ray's normalised hit weights.
        lambda_h: f32,
        /// Weight of Σ |t_j − t_mode|.
        lambda_c: f32,
        /// Rays in the batch.
        n_rays: u32,
        /// Levels used (≤ SURF_MAX_LEVELS).
        n_levels: u32,
        /// Level values τ_i, zero-padded past `n_levels`.
        levels: [f32; SURF_MAX_LEVELS],
        /// `surface_train`: the device address of the per-ray importance weights of a focused
        /// batch (low, high 32 bits); 0: every weight is 1.
        weights: [u32; 2],
        /// How the truncation count runs (`math::surface::TruncationCount`): `SURF_COUNT_RAY`
        /// over every front hit of the ray (the paper's rule); `SURF_COUNT_STRUCTURE` restarting
        /// at every front crossing of level 0; `SURF_COUNT_THROUGH` restarting there, with one
        /// hit for each structure behind the first.
        truncation_count: u32,
    }

    /// The params buffer of `plenoxel_train` (its push block would pass lavapipe's 128-byte
    /// limit with these): how rays map into the grid, early stop, the loss weights.
    struct PlenoxelParams {
        /// grid = p·scale + offset (per axis).
        scale: [f32; 3],
        offset: [f32; 3],
        /// Stop once transmittance falls below this.
        stop_thresh: f32,
        /// dL/dC = grad_scale·(C − target).
        grad_scale: f32,
        /// Weight λ of the Cauchy sparsity loss λ·Σ log(1 + 2σ²) over every shaded sample of
        /// the backward march (svox2's `lambda_sparsity`); 0: none.
        sparsity: f32,
    }

    /// The background every render and training kernel composites behind its rays,
    /// C = Σ w_j c_j + T·rgb, and, when it is learned, its gradient and optimiser state
    /// (`background_step`). One per backend, in a device buffer, so that a learned colour is
    /// updated on the device without a host round trip.
    struct Background {
        /// The colour, in [0, 1].
        rgb: [f32; 3],
        /// ≠ 0: the training kernels add dL/d`rgb` = Σ_rays dL/dC·T into `grad`.
        learn: u32,
        /// dL/d`rgb` of the step so far (float atomics); cleared by `background_step`.
        grad: [f32; 3],
        /// RMSProp running average of grad² (`background_step`).
        avg: [f32; 3],
        /// Device address (low, high 32 bits) of the `BackgroundSpheres` in front of `rgb`; 0:
        /// none (always 0 on the host: the CPU backends hold their spheres themselves).
        spheres: [u32; 2],
    }

    /// The background of a 360° capture (`--background spheres`, `math::background_msi`):
    /// `layers` spheres around `centre`, their radii evenly spaced in inverse distance
    /// (1/r_l = inv_r0 − l·inv_step), each an octahedral map of `size` × `size` texels of
    /// (σ, r, g, b). A ray is composited over the layers it leaves, nearest first, in front of
    /// `Background::rgb`, behind the grid.
    struct BackgroundSpheres {
        /// Centre of the spheres (the grid box's), scaled units.
        centre: [f32; 3],
        /// Number of spheres (0: none, the colour alone).
        layers: u32,
        /// Texels per side of each sphere's map.
        size: u32,
        /// 1 / the innermost radius.
        inv_r0: f32,
        /// Decrement of 1/r from one sphere to the next.
        inv_step: f32,
        /// ≠ 0: the training kernels add dL/d(texel values) into `grad`.
        learn: u32,
        /// Device addresses (low, high 32 bits) of the texel values (layer, row, column, then
        /// σ, r, g, b) and of their gradient.
        table: [u32; 2],
        grad: [u32; 2],
    }

    /// Per-ray output of `surface_fwd`.
    struct SurfOut {
        /// Colour composited on the background.
        rgb: [f32; 3],
        /// Final transmittance (before the background is added).
        transmittance: f32,
        /// Front-face hits composited.
        hits: u32,
    }

    /// One training view's camera as `sample_rays` reads it (`data::TrainViews`): the columns of
    /// the camera-to-world rotation (OpenGL convention, `data::Camera`), the camera centre in the
    /// scaled world, focal lengths and principal point in pixels.
    struct SampleCamera {
        x_axis: [f32; 3],
        y_axis: [f32; 3],
        z_axis: [f32; 3],
        origin: [f32; 3],
        focal: [f32; 2],
        centre: [f32; 2],
    }

    /// Per-ray output of `surface_train`: the loss terms before weighting, and hits composited.
    struct RayLoss {
        /// Σ over channels of (C − target)².
        sq_err: f32,
        /// Entropy of the normalised hit weights (0 when λH = 0).
        entropy: f32,
        /// Σ |t_j − t_mode| in scene units (0 when λc = 0).
        consistency: f32,
        hits: u32,
    }

    /// Counters of the stage-1 march (plenoxel_fwd, plenoxel_train), summed over rays; kept in
    /// the step record's header (`StepHeader::stats`).
    counters PlenoxelCounts / PlenoxelPerRay {
        /// Samples shaded (σ > SIGMA_EPS).
        shaded,
        /// Samples evaluated with σ ≤ SIGMA_EPS.
        empty,
        /// Samples jumped over by the occupancy volume.
        skipped,
        /// Gradient atomic adds (training).
        atomic_adds,
    }

    /// The header of the step record the training kernels of a step share (glsl/lib/step.glsl,
    /// twin `math::step`); the touched flags (`n`) and the touched list (`n`) follow it
    /// (`StepRecord` in glsl/lib/common.glsl). The host zeroes `count` and `stats` each step.
    struct StepHeader {
        /// Vertices touched this step: the length of the touched list.
        count: u32,
        /// Counters of the stage-1 march.
        stats: PlenoxelCounts,
        /// Vertex count: the length of the flags, and where the list starts after them.
        n: u32,
        /// Unused: the flags start 32 bytes in.
        pad: [u32; 2],
    }

    /// Counters of `surface_fwd`, summed over rays.
    counters SurfCounts {
        /// Cells read (links loaded: live cells when skipping).
        cells,
        /// Cubic solves (levels that pass min/max and segment culling, per cell read).
        solves,
        /// Solves skipped by min/max or segment culling.
        culled,
        /// Hits composited.
        hits,
        /// Hits cut off by truncation (j ≥ a).
        cut,
        /// Empty-space blocks skipped.
        blocks_skipped,
    }

    /// Counters of `surface_train`, summed over rays.
    counters TrainCounts / TrainPerRay {
        /// Cells read (live cells: corners loaded).
        cells,
        /// Cubic solves.
        solves,
        /// Solves skipped by min/max or segment culling.
        culled,
        /// Hits composited.
        hits,
        /// Hits cut off by truncation.
        cut,
        /// Hits whose δ gradient the f′ guard dropped.
        guarded,
        /// Gradient atomic adds.
        atomic_adds,
        /// Empty-space blocks skipped.
        blocks_skipped,
    }
}
