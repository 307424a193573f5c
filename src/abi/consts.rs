//! Constants shared by the kernels and the host: the one definition of each. `build.rs` reads
//! this file too and serves every constant to the GLSL as `const` in the generated
//! `abi.glsl` (included by `glsl/lib/common.glsl`), so a value changed here changes both sides.
//!
//! Each entry is `NAME: type = value;` with type `u32`, `usize` (a GLSL `uint`), `f32` or an array
//! of those; a value may use the entries above it.

abi_consts! {
    // DDA (math::dda, glsl/lib/dda.glsl).
    /// Stands for infinity (no NaN from 0·inf anywhere).
    DDA_BIG: f32 = f32::MAX;
    /// Components of `o` and `d` with magnitude < `DDA_TINY` count as zero.
    DDA_TINY: f32 = 1e-30;
    /// Initial value of the walk checksum (`math::dda::dda_hash`).
    DDA_HASH0: u32 = 2_166_136_261;
    /// A ray with a direction component of magnitude ≥ `DDA_HUGE` (2^26) misses: every nonzero
    /// plane distance `|k − o| ≥ DDA_TINY` times `1/d` then stays a normal float.
    DDA_HUGE: f32 = 67_108_864.0;
    /// Above this |t| the entry point's exact product is not formed (4097·t would overflow).
    DDA_SPLIT_MAX: f32 = 1e30;

    // Cell cubic (math::cubic, glsl/lib/cubic.glsl).
    /// Crossings closer than `CUBIC_MERGE_EPS · max(1, L)` voxel are one cluster (method.md §5).
    CUBIC_MERGE_EPS: f32 = 1e-6;
    /// Iteration cap of the safeguarded Newton/bisection in one bracket. Bisection alone would
    /// reach f32 resolution on [0, √3] in about 24 steps, so the cap is never the binding stop in
    /// practice.
    CUBIC_MAX_ITERS: u32 = 32;
    /// Newton/bisection stops when the last step is below this times max(1, L) (≈ 2 ulp at s = 1).
    CUBIC_STEP_TOL: f32 = 2.4e-7;
    /// A value of f at a critical point within `CUBIC_CRIT_SNAP · Σ|C_k|·s^k` of zero (its f32
    /// rounding noise) is taken as exactly zero: the sign walk then decides from the neighbouring
    /// values, so a tangent touch is no crossing and a triple root one crossing, instead of
    /// rounding-noise pairs. A crossing above the stress suite's floor cannot lie that close to a
    /// critical value. 2^-22.
    CUBIC_CRIT_SNAP: f32 = 2.384_185_8e-7;
    /// A coordinate of the exit point within this of a cell face is put on the face.
    CUBIC_SNAP: f32 = 1e-6;
    /// Segments longer than this (voxel) have no crossings (keeps every intermediate finite).
    CUBIC_MAX_L: f32 = 1e12;

    // Spherical harmonics of degree 2 (math::sh, glsl/lib/sh.glsl).
    /// Y_0.
    SH_C0: f32 = 0.282_094_79;
    /// |Y_1..Y_3| / coordinate.
    SH_C1: f32 = 0.488_602_51;
    /// |Y_4|, |Y_5|, |Y_7| / product of coordinates. (Digits as written in method.md.)
    #[allow(clippy::excessive_precision)]
    SH_C2: f32 = 1.092_548_43;
    /// Y_6 / (2z² − x² − y²).
    SH_C3: f32 = 0.315_391_57;
    /// Y_8 / (x² − y²).
    SH_C4: f32 = 0.546_274_22;

    // Stage-1 ray march (math::plenoxel, glsl/lib/plenoxel.glsl).
    /// Samples with trilerped σ at or below this are skipped (ReLU).
    SIGMA_EPS: f32 = 1e-8;
    /// March step in voxels.
    STEP: f32 = 0.5;
    /// Skips stop this far (voxels) before the block exit.
    SKIP_MARGIN: f32 = 1e-3;
    /// The kernels' occupancy blocks are 2^OCC_SHIFT cells per axis (the CPU twins' edge is
    /// `math::plenoxel::OCC_SHIFT_CPU`).
    OCC_SHIFT: u32 = 3;
    /// Shaded samples whose indices the forward pass records for the backward replay
    /// (plenoxel_train).
    REPLAY: usize = 32;

    // Touched flags of the step record (math::step, abi::step, glsl/lib/step.glsl; its header is
    // `buffers::StepHeader`).
    /// Touched-flag bits: stage 1's one group, stage 2's three (the optimiser updates only the
    /// groups of a vertex that received a gradient).
    TOUCH_ALL: u32 = 1;
    TOUCH_DELTA: u32 = 1;
    TOUCH_OPACITY: u32 = 2;
    TOUCH_SH: u32 = 4;
    /// Every stage-2 group.
    TOUCH_SURFACE: u32 = TOUCH_DELTA | TOUCH_OPACITY | TOUCH_SH;

    // Dispatch (gpu::Batch::dispatch_1d, glsl/lib/common.glsl flat_id).
    /// Workgroups along x in a 1-D dispatch before wrapping to y (each dimension allows ≥ 65535).
    DISPATCH_ROW_GROUPS: u32 = 32768;

    // Stage-2 rendering (math::surface, glsl/lib/surface.glsl).
    /// At most this many levels τ_i.
    SURF_MAX_LEVELS: usize = 8;
    /// Relative margin of segment culling (`surf_segment_mask`): about 80 times the rounding of
    /// the quantities it compares.
    SURF_SEGMENT_MARGIN: f32 = 1e-5;
    /// Composited hits surface_train records per ray: the truncation parameter a may not exceed
    /// this.
    SURF_MAX_HITS: usize = 8;
    /// Counting the truncation per structure, a truncated hit is passed over only while the
    /// transmittance is at least this (1/256): below it, what lies behind could change the
    /// colour by less than one step of the 8-bit images, so the ray ends there.
    SURF_PASS_MIN_T: f32 = 0.00390625;
    /// `SurfParams::truncation_count`: how the truncation count runs along a ray
    /// (`math::surface::TruncationCount`): over every front hit, restarting per structure, or
    /// restarting per structure with one hit for each structure behind the first.
    SURF_COUNT_RAY: u32 = 0;
    SURF_COUNT_STRUCTURE: u32 = 1;
    SURF_COUNT_THROUGH: u32 = 2;
    /// Relative guard on the implicit derivative's denominator f′(s) (surface_train).
    FPRIME_GUARD: f32 = 1e-3;

    // Skip structure (math::surface_blocks, glsl/lib/surface_blocks.glsl).
    /// "No block skipped yet" (an index no block has).
    SURF_NO_BLOCK: u32 = u32::MAX;
    /// Words after the block masks in a skip structure: the box of the allocated vertices, lo
    /// x, y, z then hi x, y, z (`math::surface_blocks::surf_box_span`).
    SURF_BOX_WORDS: usize = 6;
    /// Bits of a block word holding its level mask (at most 8 levels).
    SURF_MASK_BITS: u32 = 0xff;
    /// A mask-0 block's word holds its empty radius r from this bit on: every block within
    /// Chebyshev distance r of it (in blocks, inside the grid) has mask 0 as well, so a walk in it
    /// may jump to the exit of that cube of blocks. 0 ≤ r ≤ `SURF_MAX_RADIUS`; 0 for a block with
    /// levels.
    SURF_RADIUS_SHIFT: u32 = 8;
    /// Largest empty radius recorded (each of the three passes that find it reads 2·this + 1
    /// words per block).
    SURF_MAX_RADIUS: u32 = 8;
    /// Start of a block's δ range scan: `bmin = SURF_BLOCK_BIG`, `bmax = −SURF_BLOCK_BIG`.
    SURF_BLOCK_BIG: f32 = f32::MAX;

    // Training-ray sampling (cpu::sample_rays, glsl/sample_rays.comp).
    /// Side of sample_rays' sort: its workgroup size, the keys each invocation of the sort holds
    /// in registers, and the square root of a run's length.
    SAMPLE_SORT_SIDE: u32 = 64;
    /// Rays of a sorted run: a batch is ordered by key within each run of this many rays (a
    /// larger batch is sorted per run, not as a whole); one workgroup sorts a run in its
    /// registers and shared memory (4096 64-bit keys: 32 KiB, within the shared memory lavapipe
    /// and NVIDIA GPUs offer).
    SAMPLE_SORT_RAYS: u32 = SAMPLE_SORT_SIDE * SAMPLE_SORT_SIDE;

    // Loss sums (cpu::loss_sum, glsl/loss_sum.comp).
    /// Invocations of the one `loss_sum` workgroup (its local size) and its partial sums.
    LOSS_SUM_THREADS: u32 = 256;
    /// Per-ray loss fields `loss_sum` adds up at most.
    LOSS_SUM_FIELDS: u32 = 4;

    // Stage-2 regularisers and optimiser (surface::{delta_tv, rmsprop}, cpu::surface_reg).
    /// Floats per row of Lδ's directions scratch `q` (x, y, z and a pad: two aligned 64-bit
    /// words).
    Q_FLOATS: usize = 4;
    /// Chunk rows per invocation of surface_opacity_reg.
    OPACITY_REG_ROWS: u32 = 16;
    /// Row pairs per invocation of surface_rmsprop's range pass.
    RMSPROP_RANGE_ROWS: u32 = 16;
    /// Pairs where a cell's unnormalised normal has |n|² at most this are skipped (no direction).
    TINY_NORMAL2: f32 = 1e-12;
    /// Ints per row of the normal regulariser's neighbour table (layout in
    /// glsl/lib/normal_reg.glsl): [0] k, [j] the row of v + NBR_B[j], [8 + j] the row of
    /// v − NBR_B[j] (j = 1..7; −1 outside the grid or unallocated), [8] −1.
    NBR_STRIDE: usize = 16;
    /// The corner offset b (4·x + 2·y + z bits) of neighbour-table entry j and 8 + j: the face
    /// neighbours z, y, x first.
    NBR_B: [usize; 8] = [0, 1, 2, 4, 3, 5, 6, 7];
}
