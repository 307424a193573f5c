//! `eval` as a library call: Chamfer distance and F-score of a predicted point cloud against the
//! ground truth (method.md §4), both read from PLY. Both clouds are first thinned with
//! `--downsample` (the paper downsamples predicted and GT points at 0.001); an extraction is
//! already thinned at that radius, so this only changes an unthinned cloud. With the scene's
//! `scene.json` (found next to the GT cloud, or `--scene`) the figures are also split over its
//! objects ([`crate::eval::objects`]). A mesh (a PLY with faces, e.g. from `extract --mesh`) is
//! compared through points drawn on it uniformly by area. Only predicted points inside the
//! evaluation box are scored (`--box`, else the scene.json's `eval_box` when it has one: the
//! object's box in a capture whose GT is the object alone, so a floor and walls are not scored as
//! the object).

use crate::data::Aabb;
use crate::eval::objects::{load_groups, GtGroups};
use crate::eval::{evaluate_indexed, thin, EvalOptions, Metrics};
use crate::io::read_points;
use crate::math::knn::PointIndex;
use crate::mesh::ply::{has_faces, read_mesh_ply};
use anyhow::{ensure, Context, Result};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Distances at or above this are left out of the Chamfer means by default.
pub const DEFAULT_MAX_DIST: f64 = 1.5;
/// Precision/recall distance threshold by default.
pub const DEFAULT_THRESHOLD: f64 = 0.01;
/// Thinning radius of both clouds by default (the paper's downsampling).
pub const DEFAULT_DOWNSAMPLE: f64 = 0.001;
/// Points drawn on a mesh by default.
pub const DEFAULT_MESH_SAMPLES: usize = 1_000_000;

/// Options of `eval` (its command-line flags).
#[derive(clap::Args, Debug)]
pub struct EvaluateOptions {
    /// Predicted points (PLY, e.g. from `extract`), Blender units. A PLY with faces (e.g. from
    /// `extract --mesh`; --gt too) is sampled uniformly by area (--mesh-samples points).
    #[arg(long)]
    pub pred: PathBuf,
    /// Points drawn on a mesh (uniform by area, fixed seed), before the downsampling.
    #[arg(long, default_value_t = DEFAULT_MESH_SAMPLES)]
    pub mesh_samples: usize,
    /// Ground-truth points (PLY, e.g. a scene's gt_points.ply), Blender units.
    #[arg(long)]
    pub gt: PathBuf,
    /// Distances at or above this are left out of the Chamfer means.
    #[arg(long, default_value_t = DEFAULT_MAX_DIST)]
    pub max_dist: f64,
    /// Precision/recall distance threshold.
    #[arg(long, default_value_t = DEFAULT_THRESHOLD)]
    pub threshold: f64,
    /// Thin both clouds with this radius before measuring; 0 = off.
    #[arg(long, default_value_t = DEFAULT_DOWNSAMPLE)]
    pub downsample: f64,
    /// The scene's scene.json (objects and their GT point ranges, as `make-scene` writes it): split
    /// the figures over its objects. Default: the scene.json next to --gt, when there is one.
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Score only the predicted points inside this box, dataset units
    /// `xmin,ymin,zmin,xmax,ymax,zmax`. Default: the scene.json's `eval_box` (--scene, or next
    /// to --gt) when it has one, else every point.
    #[arg(
        long = "box",
        value_name = "XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    pub eval_box: Option<Vec<f32>>,
    /// Count completeness (s2d, recall) only over the GT points this mask marks: a 1-D boolean
    /// `.npy`, one flag per point of --gt as read, e.g. a forward-facing capture's
    /// `gt_points_visible.npy` (the points a training view sees; its back is never seen).
    /// Accuracy (d2s, precision) is still measured against every GT point. Default: the mask
    /// the scene.json (--scene, or next to --gt) names when it says `"layout": "forward"`.
    #[arg(long, value_name = "MASK.npy")]
    pub visible: Option<PathBuf>,
    /// Print one JSON object with every figure as the last stdout line.
    #[arg(long)]
    pub json: bool,
}

/// The box predicted points are scored in, and where it came from.
#[derive(Clone, Debug)]
pub struct ScoredBox {
    pub bounds: Aabb,
    /// `--box` or the scene.json's path.
    pub from: String,
}

/// The scene.json `--scene` names, else the one next to the GT cloud when there is one: its path
/// and contents.
fn scene_meta(opts: &EvaluateOptions) -> Result<Option<(PathBuf, serde_json::Value)>> {
    let path = match &opts.scene {
        Some(p) => p.clone(),
        None => opts.gt.with_file_name("scene.json"),
    };
    if !path.is_file() {
        return Ok(None);
    }
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let meta = serde_json::from_str(&text)
        .with_context(|| format!("{}: not valid JSON", path.display()))?;
    Ok(Some((path, meta)))
}

/// `--box`, else the `eval_box` of the scene.json (`--scene`, or next to the GT cloud) when it
/// has one; a malformed `eval_box` is an error naming the file.
fn scored_box(opts: &EvaluateOptions) -> Result<Option<ScoredBox>> {
    if let Some(v) = &opts.eval_box {
        return Ok(Some(ScoredBox {
            bounds: Aabb::from_values("--box", v)?,
            from: "--box".into(),
        }));
    }
    let Some((path, meta)) = scene_meta(opts)? else {
        return Ok(None);
    };
    let Some(b) = meta.get("eval_box") else {
        return Ok(None);
    };
    let corner = |k: &str| -> Result<Vec<f32>> {
        serde_json::from_value::<[f32; 3]>(b[k].clone())
            .map(|c| c.to_vec())
            .with_context(|| format!("{}: eval_box.{k} is not three numbers", path.display()))
    };
    let v = [corner("min")?, corner("max")?].concat();
    let flag = format!("{}: eval_box", path.display());
    Ok(Some(ScoredBox {
        bounds: Aabb::from_values(&flag, &v)?,
        from: path.display().to_string(),
    }))
}

/// `--visible`, else, for a forward-facing capture (its scene.json says `"layout": "forward"`),
/// the visibility mask its scene.json names (`visibility.file`): a forward-facing capture never
/// sees the object's back, so completeness counts what a training view sees.
fn visible_mask(opts: &EvaluateOptions) -> Result<Option<PathBuf>> {
    if opts.visible.is_some() {
        return Ok(opts.visible.clone());
    }
    let Some((path, meta)) = scene_meta(opts)? else {
        return Ok(None);
    };
    if meta["layout"] != "forward" {
        return Ok(None);
    }
    let file = meta["visibility"]["file"].as_str().with_context(|| {
        format!(
            "{}: a forward-facing capture without visibility.file (the mask of the GT points \
             a training view sees)",
            path.display()
        )
    })?;
    let mask = path.with_file_name(file);
    ensure!(
        mask.is_file(),
        "{}: visibility.file {} does not exist",
        path.display(),
        mask.display()
    );
    Ok(Some(mask))
}

/// A cloud read and thinned.
struct Loaded {
    points: Vec<[f32; 3]>,
    /// Indices of the kept points among those read or drawn.
    kept: Vec<usize>,
    /// Points read or drawn, before thinning.
    n_raw: usize,
    /// Faces of the mesh the points were drawn on, for a mesh.
    mesh_faces: Option<usize>,
}

/// Bytes each point drawn on a mesh takes until the distances are computed: the point, its copy
/// in the thinned cloud and its k-d tree entry.
const BYTES_PER_MESH_SAMPLE: f64 = 64.0;

/// Read a cloud (for a mesh: `mesh_samples` points drawn on it) and thin it.
fn load(path: &Path, radius: f64, mesh_samples: usize) -> Result<Loaded> {
    let (pts, mesh_faces) = if has_faces(path)? {
        let mesh = read_mesh_ply(path)?;
        crate::run::memory::ensure_fits(
            &format!("--mesh-samples {mesh_samples}"),
            mesh_samples as f64 * BYTES_PER_MESH_SAMPLE,
        )?;
        let pts = mesh.sample(mesh_samples, 0);
        ensure!(
            !pts.is_empty(),
            "{}: no points drawn on the mesh of {} faces (--mesh-samples {mesh_samples}, area 0?)",
            path.display(),
            mesh.faces.len()
        );
        (pts, Some(mesh.faces.len()))
    } else {
        (read_points(path)?, None)
    };
    let kept = thin(&pts, radius)?;
    Ok(Loaded {
        points: kept.iter().map(|&i| pts[i]).collect(),
        kept,
        n_raw: pts.len(),
        mesh_faces,
    })
}

/// The GT cloud's object groups: their names, the group of each kept GT point, and the scene.json
/// they came from.
struct ObjectSplit {
    names: Vec<String>,
    labels: Vec<u32>,
    path: PathBuf,
}

/// The object groups from `--scene` (an error there is the command's error), else from a
/// scene.json next to the GT cloud (a problem there goes to `note` and the split is skipped).
fn groups(
    opts: &EvaluateOptions,
    n_gt: usize,
    kept: &[usize],
    note: &mut Option<String>,
) -> Result<Option<ObjectSplit>> {
    let (path, explicit) = match &opts.scene {
        Some(p) => (p.clone(), true),
        None => (opts.gt.with_file_name("scene.json"), false),
    };
    if !explicit && !path.is_file() {
        return Ok(None);
    }
    match load_groups(&path, n_gt) {
        Ok(GtGroups { names, of_point }) => {
            let labels = kept.iter().map(|&i| of_point[i]).collect();
            Ok(Some(ObjectSplit {
                names,
                labels,
                path,
            }))
        }
        Err(e) if !explicit => {
            *note = Some(format!("no split over objects: {e:#}"));
            Ok(None)
        }
        Err(e) => Err(e),
    }
}

impl EvaluateOptions {
    /// The defaults of every flag, scoring `pred` against `gt`.
    pub fn new(pred: PathBuf, gt: PathBuf) -> EvaluateOptions {
        EvaluateOptions {
            pred,
            mesh_samples: DEFAULT_MESH_SAMPLES,
            gt,
            max_dist: DEFAULT_MAX_DIST,
            threshold: DEFAULT_THRESHOLD,
            downsample: DEFAULT_DOWNSAMPLE,
            scene: None,
            eval_box: None,
            visible: None,
            json: false,
        }
    }
}

/// What an evaluation measured.
pub struct Evaluation {
    pub metrics: Metrics,
    /// Points read, before thinning.
    pub n_pred_raw: usize,
    pub n_gt_raw: usize,
    /// Faces of the predicted and GT meshes the points were drawn on, for a mesh.
    pub pred_mesh_faces: Option<usize>,
    pub gt_mesh_faces: Option<usize>,
    /// The scene.json the figures were split over objects by.
    pub objects_from: Option<PathBuf>,
    /// Why a scene.json next to the GT cloud could not split the figures.
    pub note: Option<String>,
    /// The box the predicted points were scored in, and how many (after downsampling) lay
    /// outside it.
    pub scored_box: Option<(ScoredBox, usize)>,
    /// The mask completeness was counted over (--visible) and how many GT points (after
    /// thinning) it marks.
    pub visible: Option<(PathBuf, usize)>,
    /// Seconds reading and thinning, and finding the nearest points.
    pub load_s: f64,
    pub nn_s: f64,
}

/// A ground-truth cloud prepared once — read (or drawn on its mesh), thinned, split over its
/// objects and indexed — to score many predicted clouds against (a level sweep).
pub struct GroundTruth {
    path: PathBuf,
    cloud: Loaded,
    groups: Option<ObjectSplit>,
    note: Option<String>,
    /// `--visible`: the mask's path and its flag for each kept GT point.
    seen: Option<(PathBuf, Vec<bool>)>,
    index: PointIndex,
    /// Seconds reading, thinning and indexing it.
    pub load_s: f64,
}

impl GroundTruth {
    /// The cloud `opts.gt` (with `opts.downsample`, `opts.mesh_samples` and `opts.scene`).
    pub fn load(opts: &EvaluateOptions) -> Result<GroundTruth> {
        check(opts)?;
        let t = Instant::now();
        let cloud = load(&opts.gt, opts.downsample, opts.mesh_samples)?;
        ensure!(
            !cloud.points.is_empty(),
            "{}: the ground-truth point cloud is empty",
            opts.gt.display()
        );
        let mut note = None;
        let groups = groups(opts, cloud.n_raw, &cloud.kept, &mut note)?;
        let seen = match visible_mask(opts)? {
            Some(p) => {
                let flags = seen_of(&p, &opts.gt, &cloud)?;
                Some((p, flags))
            }
            None => None,
        };
        let index = PointIndex::new(&cloud.points)?;
        Ok(GroundTruth {
            path: opts.gt.clone(),
            cloud,
            groups,
            note,
            seen,
            index,
            load_s: t.elapsed().as_secs_f64(),
        })
    }

    /// The file it was read from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Score the cloud `opts.pred` against this ground truth (`opts.gt` must name it).
    pub fn score(&self, opts: &EvaluateOptions) -> Result<Evaluation> {
        check(opts)?;
        ensure!(
            opts.gt == self.path && visible_mask(opts)? == self.seen.as_ref().map(|s| s.0.clone()),
            "scoring against {} with a ground truth loaded from {}",
            opts.gt.display(),
            self.path.display()
        );
        let t = Instant::now();
        let pred = load(&opts.pred, opts.downsample, opts.mesh_samples)?;
        self.score_loaded(opts, pred, t.elapsed().as_secs_f64())
    }

    /// Score `pred`, read and thinned in `load_s` seconds.
    fn score_loaded(
        &self,
        opts: &EvaluateOptions,
        mut pred: Loaded,
        load_s: f64,
    ) -> Result<Evaluation> {
        let scored_box = match scored_box(opts)? {
            Some(b) => {
                let before = pred.points.len();
                pred.points.retain(|p| b.bounds.contains(*p));
                ensure!(
                    !pred.points.is_empty(),
                    "{}: none of its {before} points lies inside the evaluation box {} (from {})",
                    opts.pred.display(),
                    b.bounds,
                    b.from
                );
                let outside = before - pred.points.len();
                Some((b, outside))
            }
            None => None,
        };
        let t = Instant::now();
        let m = evaluate_indexed(
            &pred.points,
            &self.cloud.points,
            &self.index,
            self.groups
                .as_ref()
                .map(|g| (g.names.as_slice(), g.labels.as_slice())),
            self.seen.as_ref().map(|s| s.1.as_slice()),
            &EvalOptions {
                max_dist: opts.max_dist,
                threshold: opts.threshold,
            },
        )?;
        let nn_s = t.elapsed().as_secs_f64();
        ensure!(
            m.d2s_used > 0 && m.s2d_used > 0,
            "no usable distance: {} of {} predicted and {} of {} ground-truth points lie within \
             --max-dist {} of the other cloud, so the Chamfer distance is undefined (are both \
             clouds in Blender units? a cloud in millimetres is 1000× too large)",
            m.d2s_used,
            m.n_pred,
            m.s2d_used,
            m.n_gt,
            opts.max_dist
        );
        Ok(Evaluation {
            metrics: m,
            n_pred_raw: pred.n_raw,
            n_gt_raw: self.cloud.n_raw,
            pred_mesh_faces: pred.mesh_faces,
            gt_mesh_faces: self.cloud.mesh_faces,
            objects_from: self.groups.as_ref().map(|g| g.path.clone()),
            note: self.note.clone(),
            scored_box,
            visible: self
                .seen
                .as_ref()
                .map(|(p, s)| (p.clone(), s.iter().filter(|&&v| v).count())),
            load_s,
            nn_s,
        })
    }
}

/// The flag of each kept (thinned) GT point from the mask at `path`, which must hold one flag per
/// point of the GT file `gt` as read.
fn seen_of(path: &Path, gt: &Path, cloud: &Loaded) -> Result<Vec<bool>> {
    let mask = crate::grid::npz::read_mask(path)?;
    ensure!(
        mask.len() == cloud.n_raw,
        "{}: {} flags, but {} holds {} points (--visible needs one flag per GT point)",
        path.display(),
        mask.len(),
        gt.display(),
        cloud.n_raw
    );
    Ok(cloud.kept.iter().map(|&i| mask[i]).collect())
}

fn check(opts: &EvaluateOptions) -> Result<()> {
    ensure!(
        opts.max_dist > 0.0 && opts.threshold > 0.0 && opts.downsample >= 0.0,
        "--max-dist and --threshold must be positive, --downsample ≥ 0"
    );
    Ok(())
}

/// Score the cloud `opts.pred` against `opts.gt` (both read, and GT indexed, in parallel).
pub fn evaluate(opts: &EvaluateOptions) -> Result<Evaluation> {
    check(opts)?;
    let t = Instant::now();
    let (pred, gt) = rayon::join(
        || load(&opts.pred, opts.downsample, opts.mesh_samples),
        || GroundTruth::load(opts),
    );
    let (pred, gt) = (pred?, gt?);
    gt.score_loaded(opts, pred, t.elapsed().as_secs_f64())
}
