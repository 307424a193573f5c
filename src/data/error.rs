//! Typed errors of the dataset loaders (NeRF-synthetic, COLMAP, IDR). Every variant names the
//! offending file and the problem; the loaders return them wrapped in `anyhow` context, so callers
//! can still `downcast_ref`.

use std::path::PathBuf;

/// A dataset that cannot be loaded, and why.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    /// `--background learned` or `spheres` on a dataset whose images have alpha or masks.
    #[error(
        "{}: image {} has alpha (or a mask): `--background {mode}` is for images without one; \
         use `--background white` or `black` to composite on that colour",
        path.display(),
        image.display()
    )]
    AlphaWithLearnedBackground {
        /// The dataset directory.
        path: PathBuf,
        /// The first image with alpha.
        image: PathBuf,
        /// The learned mode asked for (`learned`, `spheres`).
        mode: &'static str,
    },
    /// The dataset directory does not exist or is not a directory.
    #[error("{}: dataset directory does not exist or is not a directory", path.display())]
    MissingDir {
        /// The directory given.
        path: PathBuf,
    },
    /// A required `transforms_<split>.json` is missing.
    #[error("{}: split file not found (the '{split}' split is required)", path.display())]
    MissingSplit {
        /// Split name.
        split: String,
        /// The file looked for.
        path: PathBuf,
    },
    /// The JSON does not parse or has the wrong shape.
    #[error("{}: malformed JSON at line {line}, column {column}: {msg}", path.display())]
    Json {
        /// The JSON file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// serde_json's description.
        msg: String,
    },
    /// The JSON parses but lacks something the loader needs.
    #[error("{}: {msg}", path.display())]
    Format {
        /// The JSON file.
        path: PathBuf,
        /// What is wrong.
        msg: String,
    },
    /// An image named by a frame does not exist.
    #[error("{}: image not found (frame {frame} of {})", path.display(), json.display())]
    MissingImage {
        /// The image path looked for.
        path: PathBuf,
        /// The JSON naming it.
        json: PathBuf,
        /// Frame index in that JSON.
        frame: usize,
    },
    /// An image exists but cannot be read or decoded.
    #[error("{}: cannot read image: {msg}", path.display())]
    UnreadableImage {
        /// The image.
        path: PathBuf,
        /// The reader's or decoder's message.
        msg: String,
    },
    /// Images of different sizes in one dataset (or an image that contradicts `w`/`h`).
    #[error("{}: image is {got_w}x{got_h} but {reference} is {want_w}x{want_h}", path.display())]
    MixedSizes {
        /// The image that differs.
        path: PathBuf,
        /// Its size.
        got_w: u32,
        /// Its size.
        got_h: u32,
        /// What it was compared with (another image, or the JSON's w/h).
        reference: String,
        /// The expected size.
        want_w: u32,
        /// The expected size.
        want_h: u32,
    },
    /// A transform matrix that is non-finite, singular or malformed.
    #[error("{}: frame {frame}: transform_matrix {problem}", path.display())]
    BadTransform {
        /// The JSON file.
        path: PathBuf,
        /// Frame index.
        frame: usize,
        /// What is wrong with it.
        problem: String,
    },
    /// A split with no frames.
    #[error("{}: the '{split}' split has no frames", path.display())]
    EmptySplit {
        /// The JSON file.
        path: PathBuf,
        /// Split name.
        split: String,
    },
    /// A `file_path` that leaves the dataset directory.
    #[error("{}: frame {frame}: file_path '{file_path}' points outside the dataset directory", path.display())]
    PathEscape {
        /// The JSON file.
        path: PathBuf,
        /// Frame index.
        frame: usize,
        /// The offending `file_path`.
        file_path: String,
    },
    /// A downscale factor of 0, or one larger than the images.
    #[error("{}: --downscale {factor} is invalid: {reason}", path.display())]
    BadDownscale {
        /// The dataset directory or the first image too small for the factor.
        path: PathBuf,
        /// The factor.
        factor: u32,
        /// Why.
        reason: String,
    },
    /// A directory that is none of the supported dataset layouts.
    #[error(
        "{}: not a dataset: expected transforms_train.json (NeRF-synthetic), transforms.json \
         (instant-ngp / nerfstudio), sparse/0/ or sparse/ with cameras.bin or cameras.txt \
         (COLMAP), cameras_sphere.npz (IDR/DTU), or poses_bounds.npy (LLFF)",
        path.display()
    )]
    UnknownLayout {
        /// The directory given.
        path: PathBuf,
    },
    /// A COLMAP camera model the loader cannot use.
    #[error("{}: camera {camera_id}: camera model {model} is not supported ({reason})", path.display())]
    CameraModel {
        /// cameras.txt or cameras.bin.
        path: PathBuf,
        /// The camera's id.
        camera_id: i64,
        /// The model's name (or numeric id when unknown).
        model: String,
        /// What is supported instead.
        reason: String,
    },
    /// A binary file that ends before the entries it declares.
    #[error("{}: truncated: {what}", path.display())]
    Truncated {
        /// The file.
        path: PathBuf,
        /// What was being read when it ended.
        what: String,
    },
    /// A camera pose that is non-finite or degenerate.
    #[error("{}: image '{image}': {problem}", path.display())]
    BadPose {
        /// The file holding the pose (images.txt/bin, cameras_sphere.npz).
        path: PathBuf,
        /// The image it belongs to.
        image: String,
        /// What is wrong.
        problem: String,
    },
    /// Counts that disagree (declared vs present, cameras vs images, images vs masks).
    #[error("{}: {msg}", path.display())]
    CountMismatch {
        /// The file or directory where the disagreement shows.
        path: PathBuf,
        /// The counts.
        msg: String,
    },
    /// An image or mask of a posed view that does not exist.
    #[error("{}: not found (image '{image}' posed in {})", path.display(), listed_in.display())]
    MissingViewFile {
        /// The file looked for.
        path: PathBuf,
        /// The image's name in the model.
        image: String,
        /// The file that poses it.
        listed_in: PathBuf,
    },
}
