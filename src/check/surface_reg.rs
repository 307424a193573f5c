//! Parity of the stage-2 regulariser and optimiser kernels (surface_delta_tv, surface_opacity_reg, the three
//! surface_normal_reg_* passes, surface_rmsprop) with their CPU twins, on a random surface grid
//! with a band of allocated vertices around a noisy sphere (unallocated neighbours, holes), a
//! slab allocated on the grid's outer faces, a flat block (tiny normals), σα ≤ 0, tiny and large
//! σα, and chunks inside, whole and wrapping past the end.

use super::{rel_l2, CheckRow, Compare};
use crate::abi::normal_reg::{NormalChunk, NormalPrefix, CORNERS_STRIDE, NORMALS_STRIDE};
use crate::abi::regularisers::{
    axis_neighbours, delta_tv_chunk, forward_reach, DeltaTvChunk, OpacityChunk, TvChunk,
};
use crate::abi::step::RowRange;
use crate::abi::step::{step_record, STEP_FLAGS};
use crate::abi::train::SurfaceRmsProp;
use crate::cpu::optim_args::optim_args;
use crate::cpu::surface_delta_tv::delta_tv;
use crate::cpu::surface_normal_reg_pairs::NormalRegStats;
use crate::cpu::surface_opacity_reg::surface_opacity_reg;
use crate::cpu::surface_reg::{normal_reg_passes, NormalScratch};
use crate::cpu::{surface_rmsprop, tv, SurfaceOptimArrays};
use crate::gpu::{Gpu, GpuBuffer};
use crate::grid::row_slots;
use crate::grid::SH_DIM;
use crate::kernels;
use crate::surface::delta_tv::{record_delta_tv, DeltaTvIo, Q_FLOATS};
use crate::surface::normal_reg::{record_normal_reg, NormalRegBuffers, NormalRegIo};
use crate::surface::opacity_reg_invocations;
use crate::surface::rmsprop::{record_surface_rmsprop, SurfaceOptimIo};
use anyhow::Result;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// A random stage-2 test grid: links (x-major res³), δ and σα per allocated vertex.
pub struct RegGrid {
    pub res: [u32; 3],
    pub links: Vec<i32>,
    pub delta: Vec<f32>,
    pub opacity: Vec<f32>,
}

impl RegGrid {
    pub fn slots(&self) -> u32 {
        self.links.len() as u32
    }
    pub fn allocated(&self) -> usize {
        self.delta.len()
    }
}

/// δ = |p − c| − 0.5 + noise on [−1, 1]³ sampled at res³ vertices; allocated: the band |δ| < band
/// (3 % holes punched), the x = res − 1 and z = 0 faces, and a 4³ block with constant δ (tiny
/// normals). σα uniform in [−1, 3] with every 9th exactly 0 and every 13th 1e-12.
pub fn reg_grid(seed: u64, res: u32, band: f32) -> RegGrid {
    let mut rng = Pcg64::seed_from_u64(seed);
    let r = res as usize;
    let c: [f32; 3] = std::array::from_fn(|_| rng.random_range(-0.2..0.2));
    let mut links = vec![-1i32; r * r * r];
    let mut delta = Vec::new();
    for x in 0..r {
        for y in 0..r {
            for z in 0..r {
                let p = [x, y, z].map(|i| 2.0 * i as f32 / (r - 1) as f32 - 1.0);
                let d = (0..3).map(|i| (p[i] - c[i]).powi(2)).sum::<f32>().sqrt() - 0.5;
                let flat =
                    (1..5).contains(&x) && (1..5).contains(&y) && (r - 5..r - 1).contains(&z);
                let keep =
                    (d.abs() < band || x == r - 1 || z == 0 || flat) && rng.random::<f32>() > 0.03;
                if keep {
                    links[(x * r + y) * r + z] = delta.len() as i32;
                    delta.push(if flat {
                        0.25
                    } else {
                        d + rng.random_range(-0.02..0.02)
                    });
                }
            }
        }
    }
    let opacity = (0..delta.len())
        .map(|i| match (i % 9, i % 13) {
            (0, _) => 0.0,
            (_, 0) => 1e-12,
            _ => rng.random_range(-1.0..3.0),
        })
        .collect();
    RegGrid {
        res: [res; 3],
        links,
        delta,
        opacity,
    }
}

/// A step buffer (step.glsl) for n vertices with nothing touched.
pub fn empty_step(n: usize) -> Vec<u32> {
    step_record(n, &[])
}

/// Random initial gradients, so the checks see that the kernels add.
fn random_vec(rng: &mut Pcg64, n: usize, scale: f32) -> Vec<f32> {
    (0..n).map(|_| rng.random_range(-scale..scale)).collect()
}

/// What a regulariser kernel run returned.
pub struct GpuRegOut {
    /// The gradient array after the kernel added to it.
    pub grad: Vec<f32>,
    /// The touched flags (step buffer; the normal regularisers only, empty otherwise).
    pub touched: Vec<u32>,
    /// loss[0].
    pub loss: f32,
    /// skipped[0] (the normal regularisers only; zero otherwise).
    pub skipped: u32,
    /// Device time of the kernel's dispatches, ns.
    pub ns: f64,
}

/// The kernels of the normal regularisers' passes, in order.
pub const NORMAL_REG_KERNELS: [&str; 3] = [
    "surface_normal_reg_cells",
    "surface_normal_reg_pairs",
    "surface_normal_reg_gather",
];

/// Run the normal regularisers' passes on the device (`ns`: their total), also returning the
/// per-row arrays they passed on. With `prior`, that chunk's passes run first on the same
/// per-row arrays (into outputs of their own), so `c`'s passes start from what another chunk
/// left there, as in training.
pub fn gpu_normal_reg_scratch(
    gpu: &Gpu,
    g: &RegGrid,
    grad0: &[f32],
    c: &NormalChunk,
    prior: Option<&NormalChunk>,
) -> Result<(GpuRegOut, NormalScratch)> {
    let n = g.allocated();
    let prefix = NormalPrefix::new(&g.links, &row_slots(&g.links, n), g.res);
    let bufs = NormalRegBuffers::new(gpu, &prefix)?;
    let delta = gpu.upload(&g.delta)?;
    let grad = gpu.upload(grad0)?;
    let step = gpu.upload(&empty_step(n))?;
    let loss = gpu.zeros::<f32>(1)?;
    let skipped = gpu.zeros::<u32>(1)?;
    let io = NormalRegIo {
        delta: delta.address(),
        grad: grad.address(),
        step: step.address(),
        loss: loss.address(),
        skipped: skipped.address(),
    };
    let prior_out = [
        gpu.zeros::<f32>(n.max(1))?,
        gpu.upload(&empty_step(n))?,
        gpu.zeros::<f32>(1)?,
        gpu.zeros::<u32>(1)?,
    ];
    let mut b = gpu.batch()?;
    if let Some(p) = prior {
        let io = NormalRegIo {
            delta: delta.address(),
            grad: prior_out[0].address(),
            step: prior_out[1].address(),
            loss: prior_out[2].address(),
            skipped: prior_out[3].address(),
        };
        record_normal_reg(&mut b, &bufs, &io, p)?;
    }
    record_normal_reg(&mut b, &bufs, &io, c)?;
    let t = b.submit()?;
    let out = GpuRegOut {
        grad: grad.download()?,
        touched: step.download_range(STEP_FLAGS, n)?,
        loss: loss.download::<f32>()?[0],
        skipped: skipped.download::<u32>()?[0],
        ns: NORMAL_REG_KERNELS.iter().map(|k| t.kernel_ns(k)).sum(),
    };
    let scratch = NormalScratch {
        normals: bufs.normals.download_range(0, NORMALS_STRIDE * n)?,
        corners: bufs.corners.download_range(0, CORNERS_STRIDE * n)?,
    };
    Ok((out, scratch))
}

/// Run the normal regularisers' passes on the device.
pub fn gpu_normal_reg(gpu: &Gpu, g: &RegGrid, grad0: &[f32], c: &NormalChunk) -> Result<GpuRegOut> {
    Ok(gpu_normal_reg_scratch(gpu, g, grad0, c, None)?.0)
}

/// Run surface_opacity_reg on the device.
pub fn gpu_opacity_reg(
    gpu: &Gpu,
    opacity: &[f32],
    grad0: &[f32],
    c: &OpacityChunk,
) -> Result<GpuRegOut> {
    let op = gpu.upload(opacity)?;
    let grad = gpu.upload(grad0)?;
    let loss = gpu.zeros::<f32>(1)?;
    let t = gpu.run_1d(
        &kernels::surface_opacity_reg::INFO,
        &kernels::surface_opacity_reg::Push {
            opacity: op.address(),
            grad: grad.address(),
            loss: loss.address(),
            rows: c.rows,
            start: c.start,
            count: c.count,
            lambda: c.lambda,
        },
        opacity_reg_invocations(c),
    )?;
    Ok(GpuRegOut {
        grad: grad.download()?,
        touched: Vec::new(),
        loss: loss.download::<f32>()?[0],
        skipped: 0,
        ns: t.kernel_ns("surface_opacity_reg"),
    })
}

/// Runs both surface_delta_tv stages on the device for each chunk in turn, on the same buffers
/// (q left over from a chunk must not leak into the next): grad0 + the Lδ gradients.
pub fn gpu_delta_tv(
    gpu: &Gpu,
    g: &RegGrid,
    grad0: &[f32],
    chunks: &[DeltaTvChunk],
) -> Result<Vec<f32>> {
    let n = g.allocated();
    let nbr = axis_neighbours(&g.links, &row_slots(&g.links, n), g.res);
    let reach = forward_reach(&nbr);
    let nb = gpu.upload(&nbr)?;
    let db = gpu.upload(&g.delta)?;
    let qb = gpu.upload(&vec![f32::NAN; Q_FLOATS * n])?;
    let gb = gpu.upload(grad0)?;
    let io = DeltaTvIo {
        nbr: nb.address(),
        delta: db.address(),
        q: qb.address(),
        grad: gb.address(),
    };
    let mut b = gpu.batch()?;
    for c in chunks {
        record_delta_tv(&mut b, &io, c, reach)?;
    }
    b.submit()?;
    gb.download()
}

/// Lδ on the random grid (band with holes, a slab on the grid's faces), on chunks inside, past
/// the end (wrapping) and whole, run one after another: the device against the twin
/// elementwise, and the whole chunk's twin against `tv` over the whole grid (the definition Lδ
/// shares with TVα) in aggregate.
pub fn check_delta_tv(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    let g = reg_grid(seed, 24, 0.15);
    let n = g.allocated();
    let rows = n as u32;
    let mut rng = Pcg64::seed_from_u64(seed ^ 0xde17a);
    let grad0 = random_vec(&mut rng, n, 1e-3);
    let nbr = axis_neighbours(&g.links, &row_slots(&g.links, n), g.res);
    let reach = forward_reach(&nbr);
    let whole = delta_tv_chunk(g.res, rows, 1.0, 5e-3, 0);
    let chunks = [
        delta_tv_chunk(g.res, rows, 0.1, 5e-3, (rows / 3) as u64),
        delta_tv_chunk(g.res, rows, 0.1, 5e-3, (rows - rows / 30) as u64),
        whole,
    ];
    let mut want = grad0.clone();
    for c in &chunks {
        delta_tv(&nbr, &g.delta, &mut want, c, reach, &mut Vec::new());
    }
    let got = gpu_delta_tv(gpu, &g, &grad0, &chunks)?;
    let added = |v: &[f32]| -> Vec<f32> { v.iter().zip(&grad0).map(|(a, b)| a - b).collect() };
    let scale = added(&want).iter().fold(0f32, |m, x| m.max(x.abs())) as f64;
    let mut cmp = Compare::new(1e-6 * scale, 1e-5);
    for (i, (&a, &b)) in got.iter().zip(&want).enumerate() {
        cmp.value(a as f64, b as f64, || format!("δ gradient {i}"));
    }
    // The slot-walking TV twin over the whole grid: the same derivative, other rounding.
    let (mut by_rows, mut by_slots) = (grad0.clone(), grad0.clone());
    let mut touched = vec![0u32; n];
    delta_tv(&nbr, &g.delta, &mut by_rows, &whole, reach, &mut Vec::new());
    let all_slots = TvChunk {
        res: g.res,
        start: 0,
        count: g.slots(),
        channels: 1,
        scale: whole.scale,
        touch: 0,
    };
    tv(&g.links, &g.delta, &mut by_slots, &mut touched, &all_slots);
    let l2 = rel_l2(&added(&by_rows), &added(&by_slots));
    let mut row = cmp.row(
        "surface_delta_tv",
        n,
        format!(
            "24³ band with holes and faces; chunks of 10 % inside and wrapping, then the whole \
             grid, on the same buffers; whole grid against `tv`: rel L2 {l2:.1e} (≤ 1e-5 \
             required)"
        ),
    );
    row.tolerance = "|Δ| ≤ 1e-6·max|Δgrad| + 1e-5·|cpu| elementwise".into();
    row.pass &= l2 <= 1e-5;
    Ok(row)
}

pub fn check_opacity_reg(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    let g = reg_grid(seed, 24, 0.15);
    let n = g.allocated();
    let rows = n as u32;
    let mut rng = Pcg64::seed_from_u64(seed ^ 0x5eed);
    let grad0 = random_vec(&mut rng, n, 1e-3);
    let mut cmp = Compare::new(1e-9, 1e-6);
    let mut worst_loss = 0f64;
    let cases = [
        (rows / 3, rows / 10),
        (rows - rows / 20, rows / 10),
        (0, rows),
        (rows + 5, rows * 2),
    ];
    for &(start, count) in &cases {
        let c = OpacityChunk {
            rows,
            start,
            count,
            lambda: 1e-3,
        };
        let mut want = grad0.clone();
        let loss = surface_opacity_reg(&g.opacity, &mut want, &c);
        let out = gpu_opacity_reg(gpu, &g.opacity, &grad0, &c)?;
        let (got, got_loss) = (out.grad, out.loss);
        for (i, (&a, &b)) in got.iter().zip(&want).enumerate() {
            cmp.value(a as f64, b as f64, || {
                format!("chunk {start}+{count} grad[{i}]")
            });
        }
        // The loss is a float-atomic sum of subgroup sums of terms of both signs: compare
        // relative to Σ|terms|.
        let abs_sum: f64 = (0..c.count.min(rows))
            .map(|i| g.opacity[((start % rows + i) % rows) as usize])
            .filter(|&a| a > 0.0)
            .map(|a| (c.lambda * a.ln()).abs() as f64)
            .sum();
        worst_loss = worst_loss.max((got_loss as f64 - loss).abs() / abs_sum.max(1e-30));
    }
    let mut row = cmp.row(
        "surface_opacity_reg",
        cases.len(),
        format!(
            "one owner per element; loss (float-atomic sum) |Δ|/Σ|terms| {worst_loss:.1e} (≤ 1e-5 \
             required); σα = 0, 1e-12, < 0; chunks inside, past the end (wrapping), whole, \
             count > rows"
        ),
    );
    row.pass &= worst_loss <= 1e-5;
    Ok(row)
}

/// One chunk's run of the three normal-regulariser passes: the twin's results (`st`, `ws`,
/// `want`, `want_t`) and the device's (`out`, `gs`), after chunk `prior` ran on the device.
struct NormalRun {
    start: u32,
    count: u32,
    c: NormalChunk,
    st: NormalRegStats,
    ws: NormalScratch,
    want: Vec<f32>,
    want_t: Vec<u32>,
    out: GpuRegOut,
    gs: NormalScratch,
}

/// The parity rows of the three normal-regulariser passes, from the same runs: each compares
/// its pass's output (cells: normals; pairs: each cell's corner gradients, loss, skipped pairs —
/// both within the chunk's window; gather: the gradient and the touched flags) on four chunks,
/// each run after another chunk on the same per-row arrays. No atomics in the gradient:
/// lavapipe matches the twin bit for bit; the tolerances leave room for devices whose division
/// and square root are not correctly rounded (the normals are sums and ×¼ only: exact).
fn normal_reg_rows(gpu: &Gpu, seed: u64) -> Result<Vec<CheckRow>> {
    let g = reg_grid(seed, 24, 0.2);
    let n = g.allocated();
    let rows = n as u32;
    let prefix = NormalPrefix::new(&g.links, &row_slots(&g.links, n), g.res);
    let mut rng = Pcg64::seed_from_u64(seed ^ 0xa11);
    let grad0 = random_vec(&mut rng, n, 1e-4);
    // Each chunk after another one on the same per-row arrays (whose entries outside the
    // chunk's window the passes must not read): the whole grid, then chunks of 10 % and 25 %
    // inside and one wrapping past the end.
    let cases = [
        (0, rows, (rows / 2, rows / 10)),
        (rows / 3, rows / 10, (0, rows)),
        (rows / 2, rows / 4, (rows / 3, rows / 4)),
        (rows - rows / 10, rows / 3, (rows / 5, rows / 10)),
    ];
    let mut runs = Vec::new();
    for &(start, count, (p_start, p_count)) in &cases {
        let c = prefix.chunk(start, count, 1e-2, 1e-3);
        let prior = prefix.chunk(p_start, p_count, 3e-2, 2e-3);
        let (mut want, mut want_t) = (grad0.clone(), vec![0u32; n]);
        let mut ws = NormalScratch::default();
        let st = normal_reg_passes(&prefix, &g.delta, &mut want, &mut want_t, &c, &mut ws);
        let (out, gs) = gpu_normal_reg_scratch(gpu, &g, &grad0, &c, Some(&prior))?;
        runs.push(NormalRun {
            start,
            count,
            c,
            st,
            ws,
            want,
            want_t,
            out,
            gs,
        });
    }
    let mut cmp = normal_reg_compares(&runs, &grad0);
    let (mut worst_loss, mut worst_l2, mut flags_diff, mut notes) = (0f64, 0f64, 0, Vec::new());
    for r in &runs {
        let (l2, flags, loss, note) = compare_normal_run(&mut cmp, r, &grad0);
        worst_l2 = worst_l2.max(l2);
        flags_diff += flags;
        worst_loss = worst_loss.max(loss);
        notes.push(note);
    }
    cmp[2].value(flags_diff as f64, 0.0, || "touched flags differing".into());
    Ok(normal_reg_check_rows(
        cmp,
        cases.len(),
        worst_loss,
        worst_l2,
        &notes.join("; "),
    ))
}

/// The comparisons of the cells, pairs and gather passes. Scales of the elementwise
/// tolerances: the largest finite corner gradient, the largest added gradient.
fn normal_reg_compares(runs: &[NormalRun], grad0: &[f32]) -> [Compare; 3] {
    let (mut corner_max, mut added_max) = (0f64, 0f64);
    for r in runs {
        for &v in r.ws.corners.iter().filter(|v| v.is_finite()) {
            corner_max = corner_max.max(v.abs() as f64);
        }
        for (&w, &w0) in r.want.iter().zip(grad0) {
            added_max = added_max.max((w - w0).abs() as f64);
        }
    }
    [
        Compare::new(0.0, 0.0),
        Compare::new(1e-6 * corner_max, 1e-5),
        Compare::new(1e-6 * added_max, 1e-5),
    ]
}

/// Compares one chunk's device outputs with the twin's into `cmp`; returns the rel L2 of the
/// added gradient, the number of touched flags that differ, the loss's relative difference and
/// the chunk's note.
fn compare_normal_run(
    cmp: &mut [Compare; 3],
    r: &NormalRun,
    grad0: &[f32],
) -> (f64, usize, f64, String) {
    let (start, count, c, st) = (r.start, r.count, &r.c, &r.st);
    let (ws, gs, out) = (&r.ws, &r.gs, &r.out);
    let (want, want_t) = (&r.want, &r.want_t);
    for (k, (got, want, name, stride)) in [
        (&gs.normals, &ws.normals, "normals", NORMALS_STRIDE),
        (&gs.corners, &ws.corners, "corners", CORNERS_STRIDE),
        (&out.grad, want, "grad", 1),
    ]
    .into_iter()
    .enumerate()
    {
        for (i, (&a, &b)) in got.iter().zip(want.iter()).enumerate() {
            // The per-row arrays hold what the passes wrote only within the window.
            if k < 2 && !c.rows_from_start(c.window).contains(i / stride) {
                continue;
            }
            cmp[k].value(a as f64, b as f64, || {
                format!(
                    "chunk {start}+{count} {name}[{}][{}]",
                    i / stride,
                    i % stride
                )
            });
        }
    }
    cmp[1].value(out.skipped as f64, st.skipped as f64, || {
        format!("chunk {start}+{count} skipped pairs")
    });
    let (mut num, mut den) = (0f64, 0f64);
    for ((&a, &b), &b0) in out.grad.iter().zip(want).zip(grad0) {
        num += (a as f64 - b as f64).powi(2);
        den += (b as f64 - b0 as f64).powi(2);
    }
    let l2 = (num / den.max(1e-300)).sqrt();
    let flags = out
        .touched
        .iter()
        .zip(want_t)
        .filter(|(a, b)| a != b)
        .count();
    let loss = (out.loss as f64 - st.loss).abs() / st.loss.abs().max(1e-30);
    let note = format!(
        "chunk {start}+{count}: {} cells ({} in its window), {} skipped pairs, {} touched",
        c.cells,
        c.cells_work.1,
        st.skipped,
        want_t.iter().filter(|&&t| t != 0).count()
    );
    (l2, flags, loss, note)
}

/// The cells, pairs and gather rows from their comparisons, with the worst loss and gradient
/// figures folded into their pass/fail.
fn normal_reg_check_rows(
    cmp: [Compare; 3],
    cases: usize,
    worst_loss: f64,
    worst_l2: f64,
    notes: &str,
) -> Vec<CheckRow> {
    let [c0, c1, c2] = cmp;
    let mut cells = c0.row(
        "surface_normal_reg_cells",
        cases,
        format!("cell normals, status and k, the window's rows; {notes}"),
    );
    cells.tolerance = "exact (sums and ×¼ only)".into();
    let mut pairs = c1.row(
        "surface_normal_reg_pairs",
        cases,
        format!(
            "cells' corner gradients (+∞ for cells in no pair) and skipped pairs; loss \
             (float-atomic sum of non-negative terms) rel {worst_loss:.1e} (≤ 1e-5 required); \
             {notes}"
        ),
    );
    pairs.tolerance = "|Δ| ≤ 1e-6·max|corner| + 1e-5·|cpu| elementwise; +∞ exact".into();
    pairs.pass &= worst_loss <= 1e-5;
    let mut gather = c2.row(
        "surface_normal_reg_gather",
        cases,
        format!(
            "gradient added to random initial values: rel L2 of the added gradient \
             {worst_l2:.1e} (≤ 1e-6 required); touched flags exact; {notes}"
        ),
    );
    gather.tolerance = "|Δ| ≤ 1e-6·max|Δgrad| + 1e-5·|cpu| elementwise".into();
    gather.pass &= worst_l2 <= 1e-6;
    vec![cells, pairs, gather]
}

/// The row of normal-regulariser pass `i` (see [`normal_reg_rows`]).
fn normal_reg_row(gpu: &Gpu, seed: u64, i: usize) -> Result<CheckRow> {
    Ok(normal_reg_rows(gpu, seed)?.swap_remove(i))
}

pub fn check_normal_cells(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    normal_reg_row(gpu, seed, 0)
}

pub fn check_normal_pairs(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    normal_reg_row(gpu, seed, 1)
}

pub fn check_normal_gather(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    normal_reg_row(gpu, seed, 2)
}

pub fn check_rmsprop(gpu: &Gpu, seed: u64) -> Result<CheckRow> {
    let mut cmp = Compare::new(1e-7, 1e-5);
    let part = |rows: u32, start: u32, len: u32| RowRange { rows, start, len };
    let (n, odd) = (20_000u32, 19_999u32);
    // (δ rows, σα rows), on grids of an even and an odd row count: the range passes take rows in
    // aligned pairs, so odd starts, odd lengths, wraps and the last, single row are all here.
    let ranges = [
        (n, RowRange::default(), RowRange::default()),
        (n, RowRange::all(n), RowRange::default()),
        (n, part(n, n - 1234, 3001), part(n, 5000, 6000)),
        (n, part(n, n - 1233, 3000), part(n, 4999, 6001)),
        (n, part(n, 7, n), part(n, n - 1, 1)),
        (odd, part(odd, odd - 1, 2), part(odd, 3, odd - 1)),
        (odd, part(odd, 1, odd), part(odd, odd - 3, 3)),
    ];
    for (rows, d, o) in ranges {
        rmsprop_case(gpu, seed, rows as usize, d, o, &mut cmp)?;
    }
    Ok(cmp.row(
        "surface_rmsprop",
        ranges.iter().map(|r| r.0 as usize).sum(),
        "δ, σα, 27 SH; 2/3 of vertices touched in scrambled order with every combination of \
         group bits; list pass alone; δ range pass over every row + list pass; ranges in pairs \
         from even and odd starts, of even and odd lengths, wrapping, whole from an odd start, \
         the last row alone, on 20000 and 19999 rows + list pass; fresh state, zero and \
         1e-8..1e4 gradients; untouched groups unchanged, gradients and flags cleared"
            .into(),
    ))
}

/// One RMSProp step on random state, GPU (range passes over `delta_rows` and `opacity_rows`,
/// then the list pass) against the twin; every array, flag and indirect argument compared into
/// `cmp`.
fn rmsprop_case(
    gpu: &Gpu,
    seed: u64,
    n: usize,
    delta_rows: RowRange,
    opacity_rows: RowRange,
    cmp: &mut Compare,
) -> Result<()> {
    let mut rng = Pcg64::seed_from_u64(seed);
    let mut vals = |len: usize, lo: f32, hi: f32| -> Vec<f32> {
        (0..len).map(|_| rng.random_range(lo..hi)).collect()
    };
    let mut p: [Vec<f32>; 9] = [
        vals(n, -1.0, 1.0),
        vals(n, -2.0, 4.0),
        vals(n * SH_DIM, -1.0, 1.0),
        vals(n, -1.0, 1.0),
        vals(n, -1.0, 1.0),
        vals(n * SH_DIM, -1.0, 1.0),
        vals(n, 0.0, 2.0),
        vals(n, 0.0, 2.0),
        vals(n * SH_DIM, 0.0, 2.0),
    ];
    // Fresh state on a fifth, zero gradients on a seventh, magnitudes 1e-8..1e4.
    for grp in 0..3 {
        for i in 0..p[grp + 3].len() {
            if i % 7 == grp {
                p[grp + 3][i] = 0.0;
            }
            p[grp + 3][i] *= 10f32.powi((i % 13) as i32 - 8);
            if i % 5 == grp {
                p[grp + 6][i] = 0.0;
            }
        }
    }
    // Touched vertices get the group bits 1..=7 in turn.
    let touched_list: Vec<(usize, u32)> = (0..n)
        .rev()
        .filter(|v| v % 3 != 1)
        .map(|v| (v, 1 + (v as u32 / 3) % 7))
        .collect();
    let step = step_record(n, &touched_list);
    let mut flags = vec![0u32; n];
    for &(v, bits) in &touched_list {
        flags[v] = bits;
    }
    let bufs: Vec<GpuBuffer> = p.iter().map(|v| gpu.upload(v)).collect::<Result<_>>()?;
    let sb = gpu.upload(&step)?;
    let args = gpu.zeros::<u32>(3)?;
    let h = SurfaceRmsProp {
        lr_delta: 1e-4,
        lr_opacity: 1e-2,
        lr_sh: 1e-3,
        beta: 0.95,
        eps: 1e-8,
        delta_rows,
        opacity_rows,
    };
    let a = |i: usize| bufs[i].address();
    let io = SurfaceOptimIo {
        params: [a(0), a(1), a(2)],
        grads: [a(3), a(4), a(5)],
        states: [a(6), a(7), a(8)],
    };
    let mut b = gpu.batch()?;
    record_surface_rmsprop(&mut b, &io, &sb, &args, &h)?;
    b.submit()?;
    let got_args: Vec<u32> = args.download()?;
    surface_rmsprop(SurfaceOptimArrays::from_arrays(&mut p), &mut flags, &h);
    let names = [
        "delta",
        "opacity",
        "sh",
        "grad_delta",
        "grad_opacity",
        "grad_sh",
        "state_delta",
        "state_opacity",
        "state_sh",
    ];
    for ((buf, w), name) in bufs.iter().zip(&p).zip(names) {
        let got: Vec<f32> = buf.download()?;
        for (i, (&x, &y)) in got.iter().zip(w).enumerate() {
            cmp.value(x as f64, y as f64, || {
                format!("{name}[{i}] (δ rows {delta_rows:?}, σα rows {opacity_rows:?})")
            });
        }
    }
    let got_flags: Vec<u32> = sb.download_range(STEP_FLAGS, n)?;
    for (i, (&x, &y)) in got_flags.iter().zip(&flags).enumerate() {
        cmp.value(x as f64, y as f64, || format!("touched flag {i}"));
    }
    for (i, (&x, &y)) in got_args
        .iter()
        .zip(&optim_args(touched_list.len() as u32))
        .enumerate()
    {
        cmp.value(x as f64, y as f64, || format!("indirect arg {i}"));
    }
    Ok(())
}
