//! Typed errors of the dataset loader. Every variant names the offending file and the problem;
//! the loader returns them wrapped in `anyhow` context, so callers can still `downcast_ref`.

use std::path::PathBuf;

/// A dataset that cannot be loaded, and why.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
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
    /// A downscale factor that leaves no pixels.
    #[error("{}: --downscale {factor} is invalid for {width}x{height} images", path.display())]
    BadDownscale {
        /// The first image.
        path: PathBuf,
        /// The factor.
        factor: u32,
        /// Image size.
        width: u32,
        /// Image size.
        height: u32,
    },
}
