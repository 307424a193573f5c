//! `extract` as a library call: the level-set point cloud of a trained grid as binary PLY
//! (method.md §4). For a stage-2 run (surface.npz) these are the αSurf surfaces δ = τ_i at the
//! run's levels, trimmed by raw opacity σα ≥ `--min-alpha`. For a stage-1 density grid this is the
//! Plenoxels baseline "Plen (σ = τ)": the surfaces σ = τ for each `--levels` value, with no opacity
//! trimming. With `--mesh` the same surfaces are also (or instead) written as a triangle mesh
//! ([`crate::mesh`]). With `--trim-hidden` (by default for thin stage-2 runs) the cells no
//! training camera sees inside other surfaces are dropped from both ([`crate::eval::hidden`]).

use crate::abi::extract::ExtractInput;
use crate::backend::Backend;
use crate::checkpoint::format as checkpoint;
use crate::data::ndc::Ndc;
use crate::data::{Aabb, Dataset, SceneBox};
use crate::eval::colour::Band0;
use crate::eval::extract::{
    allocated_cells, extract_sorted, to_cloud, ExtractBackend, GridFrame, KernelStats, ThinStats,
};
use crate::eval::hidden::{kept_cells, HiddenStats, HiddenTrim, Viewpoint};
use crate::eval::outer_level::{drop_outer_halo, Field as OuterField, REACH};
use crate::eval::sheets::{centre_sheets as centre_sheets_of, SheetRule};
use crate::gpu::Gpu;
use crate::grid::surface::SurfaceGrid;
use crate::grid::{npz, Grid};
use crate::io::{Extra, ExtraValues};
use crate::mesh::ply::write_mesh_ply;
use crate::mesh::{level_set_mesh, MeshInput, MeshStats};
use crate::run::dir::{ALL_STAGE1, ALL_STAGE2};
use crate::train::Category;
use anyhow::{bail, ensure, Context, Result};
use rayon::prelude::*;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Virtual rays per axis and cell face by default: method.md's 75 rays per cell (5 × 5 per axis).
pub const DEFAULT_RAYS_PER_AXIS: u32 = 5;
/// Raw opacity a stage-2 crossing needs by default (the paper's α ≥ 0.1).
pub const DEFAULT_MIN_ALPHA: f32 = 0.1;
/// Thinning radius by default, Blender units (the paper's downsampling).
pub const DEFAULT_THIN_RADIUS: f64 = 0.001;

/// Options of `extract` (its command-line flags).
#[derive(clap::Args, Debug)]
#[command(group(clap::ArgGroup::new("grid").required(true).args(["run", "ckpt"])))]
pub struct ExtractOptions {
    /// A run directory written by `train`: its `surface.npz` (stage 2) if there is one, else its
    /// `plenoxels.npz` (stage 1).
    #[arg(long)]
    pub run: Option<PathBuf>,
    /// An svox2 `ckpt.npz` (or any npz with the svox2 grid arrays) instead of `--run`.
    #[arg(long)]
    pub ckpt: Option<PathBuf>,
    /// Output point cloud PLY (binary little-endian: x, y, z, level, alpha, nx, ny, nz, and the
    /// surface colour red, green, blue as 8-bit SH band 0; Blender units).
    #[arg(long, required_unless_present = "mesh")]
    pub out: Option<PathBuf>,
    /// Output mesh PLY of the same surfaces (marching tetrahedra on the trilinear field, welded;
    /// vertices x, y, z, nx, ny, nz, level, alpha, red, green, blue (8-bit SH band 0, as MeshLab
    /// and Blender show vertex colours); triangles; Blender units). Stage-2 faces are
    /// kept where σα ≥ --min-alpha at their centroid. With or instead of --out.
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// Level values τ, comma-separated, for a stage-1 grid (density units; the paper sweeps
    /// 10,30,50,70,90,100 and reports the best single level). Default 50. A stage-2 run uses its
    /// own levels; giving --levels there is an error.
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
    pub levels: Option<Vec<f32>>,
    /// Keep a crossing only where the trilerped raw opacity σα ≥ this (stage-2 grids; a stage-1
    /// density grid has no opacity field, so it is not used there).
    #[arg(long, default_value_t = DEFAULT_MIN_ALPHA)]
    pub min_alpha: f32,
    /// R: R² virtual rays per axis and cell (origins on the lattice 0, 1/(R−1), …, 1).
    #[arg(long, default_value_t = DEFAULT_RAYS_PER_AXIS)]
    pub rays_per_axis: u32,
    /// Where the kernels run.
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    pub backend: Backend,
    /// Thinning radius in Blender units (per level, then on the union); 0 keeps every point.
    #[arg(long, default_value_t = DEFAULT_THIN_RADIUS)]
    pub thin_radius: f64,
    /// Dataset units → grid-scene scale (default: the one the run trained with, recorded in its
    /// run.json; for --ckpt and older runs the NeRF-synthetic box's 2/3).
    #[arg(long)]
    pub scene_scale: Option<f32>,
    /// Initial capacity of the device point buffer (default: min(upper bound, 2²¹) points).
    #[arg(long, hide = true)]
    pub capacity: Option<usize>,
    /// Drop the points (and mesh faces) of cells that no training view sees and that other
    /// surfaces enclose (the inner level sets of solids; an unseen underside open below stays).
    /// `auto`: on for a stage-2 run of category thin in a box, off otherwise (semi-transparent
    /// layers are seen through; stage-1 grids are the paper's Plenoxels baseline; a
    /// forward-facing capture in NDC sees what lies behind a wire guard only through its gaps,
    /// which the trim's occupancy closes). Needs the training cameras: without them `on` is an
    /// error and `auto` warns and keeps every cell.
    #[arg(long, value_enum, default_value_t = Switch::Auto)]
    pub trim_hidden: Switch,
    /// Drop the points (and mesh faces) of the outermost level where, within 1.5 cells inward
    /// along the normal, the field reaches the level two above it: around a part that thick,
    /// the outermost level is a shell about a cell out, and the higher levels locate the part;
    /// thin wires, whose field peaks below that level, keep it. `auto`: on for a stage-2 run of
    /// category thin, off otherwise (a semi-transparent layer's outer level is often its only
    /// good one).
    #[arg(long, value_enum, default_value_t = Switch::Auto)]
    pub trim_outer: Switch,
    /// Move the points of thin sheets onto the sheet: where, inward along a point's normal, the
    /// field falls below the lowest level within 4 cells (the part ends: no solid's face) and the
    /// normals around it are nearly parallel (a sheet, not a wire), the point moves inward by half
    /// that distance. A part thinner than stage 1 resolves (a blade, a board a cell thick) is a
    /// bump about four cells wide whose level sets cross it on both sides; this puts both faces
    /// on its middle. Points only (a `--mesh` is left as extracted). `auto`: on for a stage-2 run
    /// of category thin in a box, off otherwise (a semi-transparent object's nested shells are
    /// real surfaces).
    #[arg(long, value_enum, default_value_t = Switch::Auto)]
    pub sheets: Switch,
    /// Keep only the points, and the mesh faces whose centroid is, inside this box: dataset units
    /// `xmin,ymin,zmin,xmax,ymax,zmax` (e.g. the object's box in a capture, leaving out the floor
    /// and walls).
    #[arg(
        long = "box",
        value_name = "XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    pub keep_box: Option<Vec<f32>>,
    /// The dataset whose training cameras `--trim-hidden` uses (default: the run's).
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Print one JSON object with the counts and timings as the last stdout line.
    #[arg(long)]
    pub json: bool,
}

/// `--trim-hidden`, `--trim-outer`, `--sheets`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Switch {
    /// On for stage-2 runs of category thin, off otherwise.
    Auto,
    On,
    Off,
}

/// The field to extract: a stage-1 density grid, or a stage-2 surface grid (with the category
/// it trained for, when its checkpoint names one).
enum Field {
    Density(Grid),
    Surface(SurfaceGrid, Option<Category>),
}

/// Load the grid named by `--run` or `--ckpt`.
fn load_grid(opts: &ExtractOptions) -> Result<(Field, PathBuf)> {
    if let Some(ckpt) = &opts.ckpt {
        return Ok((Field::Density(npz::load_svox2(ckpt)?), ckpt.clone()));
    }
    let run = opts.run.as_ref().context("give --run or --ckpt")?;
    let surface = crate::checkpoint::path::<crate::surface::SurfaceStage>(run);
    if surface.exists() {
        let ck = crate::checkpoint::surface::load(&surface)?;
        let category = serde_json::from_value(ck.meta["config"]["category"].clone()).ok();
        return Ok((Field::Surface(ck.grid, category), surface));
    }
    let all_stage2 = run.join(ALL_STAGE2);
    ensure!(
        !crate::checkpoint::path::<crate::surface::SurfaceStage>(&all_stage2).exists(),
        "{} is a `--stage all` run: give its stage-2 run {} (or its stage-1 run {})",
        run.display(),
        all_stage2.display(),
        run.join(ALL_STAGE1).display()
    );
    let path = crate::run::dir::plenoxels_checkpoint(run, "extract --run")?;
    Ok((Field::Density(checkpoint::load(&path)?.grid), path))
}

impl ExtractOptions {
    /// The defaults of every flag, extracting the grid of the run `run` into `out`.
    pub fn for_run(run: PathBuf, out: PathBuf) -> ExtractOptions {
        ExtractOptions {
            run: Some(run),
            ckpt: None,
            out: Some(out),
            mesh: None,
            levels: None,
            min_alpha: DEFAULT_MIN_ALPHA,
            rays_per_axis: DEFAULT_RAYS_PER_AXIS,
            backend: Backend::Auto,
            thin_radius: DEFAULT_THIN_RADIUS,
            scene_scale: None,
            capacity: None,
            trim_hidden: Switch::Auto,
            trim_outer: Switch::Auto,
            sheets: Switch::Auto,
            keep_box: None,
            data: None,
            json: false,
        }
    }
}

/// What an extraction did.
#[derive(Clone, Debug, Serialize)]
pub struct ExtractReport {
    /// The checkpoint read.
    pub grid: PathBuf,
    /// A stage-2 grid (αSurf surfaces, trimmed by opacity) rather than a density grid.
    pub surface: bool,
    pub res: [u32; 3],
    pub levels: Vec<f32>,
    pub min_alpha: f32,
    /// Allocated vertices of the field.
    pub vertices: usize,
    /// Cells with 8 allocated corners.
    pub cells: usize,
    /// The point cloud (`--out`).
    pub points: Option<PointsReport>,
    /// The mesh (`--mesh`).
    pub mesh: Option<MeshReport>,
    pub load_ms: f64,
    pub total_s: f64,
}

/// What the point extraction did.
#[derive(Clone, Debug, Serialize)]
pub struct PointsReport {
    pub out: PathBuf,
    pub rays_per_axis: u32,
    /// The device's name, or "cpu".
    pub backend: String,
    pub kernel: KernelStats,
    /// The hidden-surface trimming (`--trim-hidden`), when on.
    pub hidden: Option<HiddenStats>,
    /// Points of the outermost level dropped as a halo (`--trim-outer`), when on.
    pub outer_dropped: Option<usize>,
    /// Points moved onto a thin sheet's middle (`--sheets`), when on.
    pub sheets_moved: Option<usize>,
    pub thin: ThinStats,
    /// Points written.
    pub points: usize,
    pub thin_radius: f64,
    pub write_ms: f64,
}

/// What the mesh extraction did.
#[derive(Clone, Debug, Serialize)]
pub struct MeshReport {
    pub out: PathBuf,
    /// The hidden-surface trimming (`--trim-hidden`), when on.
    pub hidden: Option<HiddenStats>,
    /// Faces of the outermost level dropped as a halo (`--trim-outer`), when on.
    pub outer_dropped: Option<usize>,
    pub stats: MeshStats,
    pub write_ms: f64,
}

/// Extract the surfaces of the grid `opts` name into `opts.out` (points, on `gpu`; `None`: the CPU
/// twin) and `opts.mesh` (a mesh, on the CPU).
pub fn extract(opts: &ExtractOptions, gpu: Option<&Gpu>) -> Result<ExtractReport> {
    let t0 = Instant::now();
    check_sampling(opts)?;
    let (scene_scale, ndc) = scene_space(opts)?;
    ensure!(
        opts.min_alpha.is_finite(),
        "--min-alpha must be a finite number, got {}",
        opts.min_alpha
    );
    ensure!(
        opts.out.is_some() || opts.mesh.is_some(),
        "give --out (points) or --mesh (a mesh), or both"
    );
    ensure!(
        opts.out.is_none() || opts.out != opts.mesh,
        "--out and --mesh name the same file"
    );
    let keep_box = keep_box(opts)?;
    let (field, path) = load_grid(opts)?;
    for out in opts.out.iter().chain(&opts.mesh) {
        crate::run::outputs::check_output_file(out, &[&path])?;
    }
    let load_ms = t0.elapsed().as_secs_f64() * 1e3;
    let (res, links) = field.res_links();
    let cells = allocated_cells(res, links)?;
    let (values, opacity, levels) = match &field {
        Field::Density(g) => (&g.density, None, opts.levels.clone().unwrap_or(vec![50.0])),
        Field::Surface(g, _) => {
            ensure!(
                opts.levels.is_none(),
                "--levels applies to stage-1 grids; {} has its own levels {:?}",
                path.display(),
                g.levels
            );
            (&g.delta, Some(g.opacity.as_slice()), g.levels.clone())
        }
    };
    ensure!(!levels.is_empty(), "--levels: give at least one level");
    ensure!(
        levels.iter().all(|l| l.is_finite()),
        "--levels: every level must be finite, got {levels:?}"
    );
    // A stage-1 grid renders max(σ, 0): a level at or below 0 is no surface of it.
    ensure!(
        matches!(field, Field::Surface(..)) || levels.iter().all(|&l| l > 0.0),
        "--levels: density levels must be positive (the rendered density is max(σ, 0)), got \
         {levels:?}"
    );
    let frame = field.frame(scene_scale, ndc);
    // `on` needs the cameras; `auto` goes on without them (a run moved away from its dataset
    // still extracts), and says so.
    let trim = match (opts.trim_hidden, &field) {
        (Switch::On, _) => Some(training_cameras(opts, &frame)?),
        (Switch::Auto, Field::Surface(_, Some(Category::Thin))) if ndc.is_none() => {
            match training_cameras(opts, &frame) {
                Ok(c) => Some(c),
                Err(e) => {
                    eprintln!("warning: hidden surfaces not trimmed: {e:#}");
                    None
                }
            }
        }
        _ => None,
    };
    let surfaces = Surfaces {
        cells: &cells,
        links,
        values,
        opacity,
        sh: field.sh(),
        levels: &levels,
        res,
        frame,
        cameras: trim.as_deref(),
        trim_outer: trim_outer(opts, &field),
        centre_sheets: centre_sheets(opts, &field, ndc.is_some()),
        keep_box,
    };
    let points = match &opts.out {
        Some(out) => Some(write_points(opts, &surfaces, out, gpu)?),
        None => None,
    };
    let mesh = match &opts.mesh {
        Some(out) => Some(write_mesh(opts, &surfaces, out)?),
        None => None,
    };
    Ok(ExtractReport {
        grid: path,
        surface: matches!(field, Field::Surface(..)),
        res,
        levels,
        min_alpha: opts.min_alpha,
        vertices: values.len(),
        cells: cells.len(),
        points,
        mesh,
        load_ms,
        total_s: t0.elapsed().as_secs_f64(),
    })
}

/// Refuse a ray count or thinning radius no extraction can use.
fn check_sampling(opts: &ExtractOptions) -> Result<()> {
    ensure!(
        (1..=64).contains(&opts.rays_per_axis),
        "--rays-per-axis must be in 1..=64, got {}",
        opts.rays_per_axis
    );
    ensure!(
        opts.thin_radius >= 0.0 && opts.thin_radius.is_finite(),
        "--thin-radius must be ≥ 0"
    );
    Ok(())
}

/// The scene scales `extract` accepts: far past any dataset's units either way, short of the
/// floats' range (points written back would overflow or vanish).
const SCENE_SCALES: std::ops::RangeInclusive<f32> = 1e-6..=1e6;

/// Dataset units → grid-scene scale: `--scene-scale`, else the run's recorded one, else the
/// NeRF-synthetic box's; and the NDC space the run recorded (forward-facing captures), which
/// `--scene-scale` cannot be combined with.
fn scene_space(opts: &ExtractOptions) -> Result<(f32, Option<Ndc>)> {
    let info = opts
        .run
        .as_ref()
        .and_then(|r| crate::run::read_info(r).ok());
    let ndc = info.as_ref().and_then(|i| i.ndc);
    if let (Some(s), Some(_)) = (opts.scene_scale, ndc) {
        bail!(
            "--scene-scale {s}: the run was trained in NDC (a forward-facing capture), which \
             maps its grid back to dataset units by itself; leave --scene-scale out"
        );
    }
    let scale = opts
        .scene_scale
        .or(info.and_then(|i| i.scene_scale))
        .unwrap_or(SceneBox::default().scale);
    ensure!(
        SCENE_SCALES.contains(&scale),
        "--scene-scale {scale}: expected {:e} ..= {:e} (dataset units → the grid's world; \
         NeRF-synthetic 2/3)",
        SCENE_SCALES.start(),
        SCENE_SCALES.end()
    );
    Ok((scale, ndc))
}

/// `--box`, checked.
fn keep_box(opts: &ExtractOptions) -> Result<Option<Aabb>> {
    opts.keep_box
        .as_deref()
        .map(|v| Aabb::from_values("--box", v))
        .transpose()
}

/// Whether thin sheets' points move onto the sheet (`--sheets`; `auto`: thin stage-2 runs in a
/// box).
fn centre_sheets(opts: &ExtractOptions, field: &Field, ndc: bool) -> bool {
    match opts.sheets {
        Switch::On => true,
        Switch::Auto => !ndc && matches!(field, Field::Surface(_, Some(Category::Thin))),
        Switch::Off => false,
    }
}

/// Whether the outermost level's halo is dropped (`--trim-outer`; `auto`: thin stage-2 runs).
fn trim_outer(opts: &ExtractOptions, field: &Field) -> bool {
    match opts.trim_outer {
        Switch::On => true,
        Switch::Auto => matches!(field, Field::Surface(_, Some(Category::Thin))),
        Switch::Off => false,
    }
}

impl Field {
    fn res_links(&self) -> ([u32; 3], &[i32]) {
        match self {
            Field::Density(g) => (g.res, &g.links),
            Field::Surface(g, _) => (g.res, &g.links),
        }
    }

    /// The SH coefficients, 27 per allocated vertex.
    fn sh(&self) -> &[f32] {
        match self {
            Field::Density(g) => &g.sh,
            Field::Surface(g, _) => &g.sh,
        }
    }

    fn frame(&self, scene_scale: f32, ndc: Option<Ndc>) -> GridFrame {
        let (res, center, radius) = match self {
            Field::Density(g) => (g.res, g.center, g.radius),
            Field::Surface(g, _) => (g.res, g.center, g.radius),
        };
        GridFrame {
            res,
            center,
            radius,
            scene_scale,
            ndc,
        }
    }
}

/// One cloud of a level sweep: level `level` of a stage-1 grid into `out`, with the cells no
/// training view sees inside other surfaces trimmed (`extract --trim-hidden on`) or not (`off`),
/// and thin sheets' points centred (`--sheets on`) or not.
pub struct LevelJob {
    pub level: f32,
    pub trim_hidden: bool,
    pub centre_sheets: bool,
    pub out: PathBuf,
}

/// `extract --levels L --trim-hidden on|off --out P` for each job, from one load of the stage-1
/// grid `opts` names (its other options apply to every job): the Plenoxels level sweep. The
/// grid, its cells and the training cameras are read once; each job has its own result (a
/// level with no surface fails alone) with its seconds: the shared load's and its own, what
/// the job alone would have taken.
pub fn extract_levels(
    opts: &ExtractOptions,
    jobs: &[LevelJob],
    gpu: Option<&Gpu>,
) -> Result<Vec<Result<(PointsReport, f64)>>> {
    let t0 = Instant::now();
    check_sampling(opts)?;
    let (frame_scale, ndc) = scene_space(opts)?;
    let keep_box = keep_box(opts)?;
    let (field, path) = load_grid(opts)?;
    let Field::Density(grid) = &field else {
        bail!(
            "{}: a level sweep takes a stage-1 density grid",
            path.display()
        );
    };
    let cells = allocated_cells(grid.res, &grid.links)?;
    let frame = field.frame(frame_scale, ndc);
    let cameras = jobs
        .iter()
        .any(|j| j.trim_hidden)
        .then(|| training_cameras(opts, &frame).map_err(|e| format!("{e:#}")));
    let outer = trim_outer(opts, &field);
    let load_s = t0.elapsed().as_secs_f64();
    Ok(jobs
        .iter()
        .map(|job| {
            let t = Instant::now();
            ensure!(job.level.is_finite(), "level {} is not finite", job.level);
            crate::run::outputs::check_output_file(&job.out, &[&path])?;
            let trim = match (&cameras, job.trim_hidden) {
                (Some(Ok(c)), true) => Some(c.as_slice()),
                (Some(Err(e)), true) => bail!("{e}"),
                _ => None,
            };
            let surfaces = Surfaces {
                cells: &cells,
                links: &grid.links,
                values: &grid.density,
                opacity: None,
                sh: &grid.sh,
                levels: &[job.level],
                res: grid.res,
                frame,
                cameras: trim,
                trim_outer: outer,
                centre_sheets: job.centre_sheets,
                keep_box,
            };
            let report = write_points(opts, &surfaces, &job.out, gpu)?;
            Ok((report, load_s + t.elapsed().as_secs_f64()))
        })
        .collect())
}

/// The level sets to extract: the field on the allocated vertices and where it lies.
struct Surfaces<'a> {
    cells: &'a [u32],
    links: &'a [i32],
    values: &'a [f32],
    opacity: Option<&'a [f32]>,
    /// SH coefficients (27 per allocated vertex): the points' and vertices' colour.
    sh: &'a [f32],
    levels: &'a [f32],
    res: [u32; 3],
    frame: GridFrame,
    /// Training camera centres in grid coordinates, when hidden surfaces are trimmed.
    cameras: Option<&'a [Viewpoint]>,
    /// Drop the outermost level's halo around thick parts ([`crate::eval::outer_level`]).
    trim_outer: bool,
    /// Move thin sheets' points onto the sheet ([`crate::eval::sheets`]).
    centre_sheets: bool,
    /// `--box`: keep only what lies inside it (dataset units).
    keep_box: Option<Aabb>,
}

impl Surfaces<'_> {
    fn field(&self) -> OuterField<'_> {
        OuterField {
            res: self.res,
            links: self.links,
            values: self.values,
        }
    }

    /// The 8-bit surface colour at each point (Blender units).
    fn colours(&self, points: &[[f32; 3]]) -> Vec<[u8; 3]> {
        let band0 = Band0 {
            res: self.res,
            links: self.links,
            sh: self.sh,
        };
        points
            .par_iter()
            .map(|p| band0.rgb_at(self.frame.blender_to_grid(*p)))
            .collect()
    }
}

/// The training cameras' centres as the trimming looks toward them, from `--data` or the run's
/// dataset.
fn training_cameras(opts: &ExtractOptions, frame: &GridFrame) -> Result<Vec<Viewpoint>> {
    let info = opts.run.as_ref().map(|r| crate::run::read_info(r));
    let dir = match (&opts.data, info) {
        (Some(d), _) => d.clone(),
        (None, Some(Ok(i))) => i.data,
        (None, Some(Err(e))) => bail!(
            "--trim-hidden needs the training cameras: {e:#} (pass --data, or --trim-hidden off)"
        ),
        (None, None) => bail!(
            "--trim-hidden needs the training cameras: pass --data with --ckpt (or --trim-hidden \
             off)"
        ),
    };
    let poses = Dataset::train_poses(&dir)
        .context("--trim-hidden needs the training cameras (or pass --trim-hidden off)")?;
    Ok(poses
        .iter()
        .map(|c2w| frame.viewpoint(c2w.w_axis.truncate().to_array()))
        .collect())
}

/// The thinned point cloud of the surfaces (virtual rays on `gpu`), written to `out`.
fn write_points(
    opts: &ExtractOptions,
    s: &Surfaces,
    out: &Path,
    gpu: Option<&Gpu>,
) -> Result<PointsReport> {
    let inp = ExtractInput {
        cells: s.cells,
        links: s.links,
        field: s.values,
        opacity: s.opacity,
        levels: s.levels,
        res: s.res,
        rays_per_axis: opts.rays_per_axis,
        min_opacity: opts.min_alpha,
    };
    let backend = match gpu {
        Some(g) => ExtractBackend::Vulkan(g),
        None => ExtractBackend::Cpu,
    };
    let (mut points, kernel) = extract_sorted(backend, &inp, opts.capacity)?;
    let hidden = s.cameras.map(|cameras| {
        let cells: Vec<u32> = points.iter().map(|p| p.cell).collect();
        let (kept, stats) = kept_cells(s.res, &cells, cameras, &HiddenTrim::default());
        points.retain(|p| kept.holds(p.cell));
        stats
    });
    let outer_dropped = s
        .trim_outer
        .then(|| drop_outer_halo(&mut points, &s.field(), s.levels, REACH));
    let sheets_moved = s
        .centre_sheets
        .then(|| centre_sheets_of(&mut points, &s.field(), s.levels[0], &SheetRule::default()));
    let (mut cloud, thin) = to_cloud(&points, s.levels, &s.frame, opts.thin_radius)?;
    if let Some(b) = &s.keep_box {
        cloud.retain(|p| b.contains(*p));
    }
    let colours = s.colours(&cloud.points);
    for (c, name) in ["red", "green", "blue"].into_iter().enumerate() {
        cloud.extras.push(Extra {
            name: name.into(),
            values: ExtraValues::UChar(colours.iter().map(|rgb| rgb[c]).collect()),
        });
    }
    ensure!(
        !cloud.points.is_empty(),
        "no surface points at levels {:?} ({}){}; nothing written",
        s.levels,
        field_range(s.values),
        s.keep_box
            .map_or(String::new(), |b| format!(" inside --box {b}"))
    );
    let t_w = Instant::now();
    crate::io::write_ply(out, &cloud)?;
    Ok(PointsReport {
        out: out.to_path_buf(),
        rays_per_axis: opts.rays_per_axis,
        backend: gpu.map_or("cpu".to_string(), |g| g.info().name.clone()),
        kernel,
        hidden,
        outer_dropped,
        sheets_moved,
        thin,
        points: cloud.points.len(),
        thin_radius: opts.thin_radius,
        write_ms: t_w.elapsed().as_secs_f64() * 1e3,
    })
}

/// The welded triangle mesh of the surfaces (marching tetrahedra on the CPU), written to `out`.
fn write_mesh(opts: &ExtractOptions, s: &Surfaces, out: &Path) -> Result<MeshReport> {
    let inp = MeshInput {
        cells: s.cells,
        links: s.links,
        field: s.values,
        opacity: s.opacity,
        levels: s.levels,
        res: s.res,
        min_opacity: opts.min_alpha,
    };
    let (mut mesh, mut stats) = level_set_mesh(&inp, &s.frame)?;
    let hidden = s.cameras.map(|cameras| {
        // Each face in the cell of its centroid.
        let cell_of = |f: &[u32; 3]| {
            let c: [f32; 3] = std::array::from_fn(|i| {
                f.iter()
                    .map(|&v| mesh.positions[v as usize][i])
                    .sum::<f32>()
                    / 3.0
            });
            let g = s.frame.blender_to_grid(c);
            let q: [u32; 3] =
                std::array::from_fn(|i| (g[i].floor().max(0.0) as u32).min(s.res[i] - 2));
            (q[0] * s.res[1] + q[1]) * s.res[2] + q[2]
        };
        let face_cells: Vec<u32> = mesh.faces.iter().map(cell_of).collect();
        let (kept, hidden) = kept_cells(s.res, &face_cells, cameras, &HiddenTrim::default());
        mesh.retain_faces(|i| kept.holds(face_cells[i]));
        stats = MeshStats::of(&mesh, s.levels, stats.wall_ms + hidden.wall_ms);
        hidden
    });
    let outer_dropped = (s.trim_outer && s.levels.len() >= 3).then(|| {
        // A face of the outermost level, from its centroid along its vertices' mean normal (a
        // world direction; to grid coordinates by the box's per-axis scale).
        let t0 = Instant::now();
        let field = s.field();
        let outer = s.levels[0];
        let halo: Vec<bool> = mesh
            .faces
            .iter()
            .map(|f| {
                if mesh.level[f[0] as usize] != outer {
                    return false;
                }
                let mean = |v: &[[f32; 3]]| -> [f32; 3] {
                    std::array::from_fn(|i| f.iter().map(|&k| v[k as usize][i]).sum::<f32>() / 3.0)
                };
                let o = s.frame.blender_to_grid(mean(&mesh.positions));
                let dir = s.frame.direction_to_grid(o, mean(&mesh.normals));
                field.reaches(o, dir, s.levels[2], REACH)
            })
            .collect();
        let before = mesh.faces.len();
        mesh.retain_faces(|i| !halo[i]);
        stats = MeshStats::of(
            &mesh,
            s.levels,
            stats.wall_ms + t0.elapsed().as_secs_f64() * 1e3,
        );
        before - mesh.faces.len()
    });
    if let Some(b) = &s.keep_box {
        let inside: Vec<bool> = mesh
            .faces
            .iter()
            .map(|f| {
                b.contains(std::array::from_fn(|i| {
                    f.iter()
                        .map(|&v| mesh.positions[v as usize][i])
                        .sum::<f32>()
                        / 3.0
                }))
            })
            .collect();
        mesh.retain_faces(|i| inside[i]);
        stats = MeshStats::of(&mesh, s.levels, stats.wall_ms);
    }
    ensure!(
        !mesh.faces.is_empty(),
        "no surface faces at levels {:?} ({}){}; nothing written",
        s.levels,
        field_range(s.values),
        s.keep_box
            .map_or(String::new(), |b| format!(" inside --box {b}"))
    );
    mesh.colour = s.colours(&mesh.positions);
    let t_w = Instant::now();
    write_mesh_ply(out, &mesh)?;
    Ok(MeshReport {
        out: out.to_path_buf(),
        stats,
        hidden,
        outer_dropped,
        write_ms: t_w.elapsed().as_secs_f64() * 1e3,
    })
}

/// The field's range over the allocated vertices, for messages (an empty grid says so).
fn field_range(v: &[f32]) -> String {
    match v.first() {
        None => "the grid holds no vertex".into(),
        Some(&first) => {
            let (lo, hi) = v
                .iter()
                .fold((first, first), |(a, b), &x| (a.min(x), b.max(x)));
            format!("field range {lo} ..= {hi}")
        }
    }
}
