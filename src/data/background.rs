//! What rays are composited on (`--background`): the colour behind every render and training
//! pass, and the colour images with alpha (or masks) are composited on at load.

use serde::{Deserialize, Serialize};

/// The background of a run.
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BackgroundMode {
    /// What the data calls for: white for images with alpha (or masks) and for forward-facing
    /// captures in NDC (whose grid reaches infinite depth), spheres for images without alpha
    /// in a box (a 360° capture whose views see a room); resuming, or stage 2 from a run
    /// directory: that run's.
    #[default]
    Auto,
    /// White (1, 1, 1): NeRF-synthetic practice.
    White,
    /// Black (0, 0, 0).
    Black,
    /// A constant RGB colour trained with the scene, for images without alpha or masks (real
    /// photos of an object in front of a plain backdrop).
    Learned,
    /// Learned spheres around the grid box in front of a learned colour: a 360° capture whose
    /// rays see a room behind the object (svox2's background for Tanks and Temples). Stage 1
    /// learns them; stage 2 keeps them.
    Spheres,
}

impl BackgroundMode {
    /// The colour images are composited on at load, and a fixed background's colour: white
    /// (also `Auto`'s: it resolves to white where images have alpha), black, or, learned, mid grey (images with alpha are refused then, so it composites
    /// nothing; a learned run starts from its images' border colour, `checkpoint::BackgroundRecord`).
    pub fn initial_rgb(self) -> [f32; 3] {
        match self {
            BackgroundMode::Auto | BackgroundMode::White => [1.0; 3],
            BackgroundMode::Black => [0.0; 3],
            BackgroundMode::Learned | BackgroundMode::Spheres => [0.5; 3],
        }
    }

    /// `Auto` resolved for a dataset: whether any image had alpha, whether its grid lies in
    /// NDC; other modes as they are.
    pub fn resolve(self, had_alpha: bool, ndc: bool) -> Self {
        match self {
            BackgroundMode::Auto if had_alpha || ndc => BackgroundMode::White,
            BackgroundMode::Auto => BackgroundMode::Spheres,
            m => m,
        }
    }

    /// What records written before the background was recorded trained with (serde's default
    /// for them).
    pub fn unrecorded() -> Self {
        BackgroundMode::White
    }

    /// Whether the colour is trained.
    pub fn learned(self) -> bool {
        matches!(self, BackgroundMode::Learned | BackgroundMode::Spheres)
    }

    /// Whether the background has spheres.
    pub fn spheres(self) -> bool {
        self == BackgroundMode::Spheres
    }

    /// The name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            BackgroundMode::Auto => "auto",
            BackgroundMode::White => "white",
            BackgroundMode::Black => "black",
            BackgroundMode::Learned => "learned",
            BackgroundMode::Spheres => "spheres",
        }
    }
}
