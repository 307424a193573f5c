//! `alphasurf make-scene`: writes a built-in procedural scene as a NeRF-synthetic dataset with
//! exact ground truth (see `crate::scene`).

use crate::scene::{generate, GenerateOptions, SceneKind};
use std::io::IsTerminal;
use std::path::PathBuf;

/// Arguments of `make-scene`.
#[derive(clap::Args, Debug)]
pub struct MakeSceneArgs {
    /// Which scene.
    #[arg(long, value_enum)]
    pub kind: SceneKind,
    /// Output directory (created if needed). It is written beside itself (`.NAME.partial`) and
    /// swapped in when complete, so an interrupted run leaves no half dataset.
    #[arg(long)]
    pub out: PathBuf,
    /// Replace the scene `make-scene` wrote before in `--out` (only such a scene: a folder
    /// holding anything else is never replaced; files of yours beside the scene are kept).
    #[arg(long)]
    pub overwrite: bool,
    /// Image width and height in pixels.
    #[arg(long, default_value_t = 256)]
    pub res: u32,
    /// Training views (val gets views/10, test views/5, at least 1 each).
    #[arg(long, default_value_t = 100)]
    pub views: u32,
    /// Seed of scene details, cameras and ground-truth samples.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Samples per pixel along each axis (spp = N²; at most 32).
    #[arg(long, default_value_t = 4)]
    pub spp: u32,
    /// Ground-truth point spacing (sqrt of area per point), Blender units.
    #[arg(long, default_value_t = 0.0019)]
    pub gt_spacing: f64,
}

/// Runs `make-scene`.
pub fn run(args: &MakeSceneArgs) -> anyhow::Result<()> {
    let opts = GenerateOptions {
        kind: args.kind,
        res: args.res,
        views: args.views,
        seed: args.seed,
        spp_side: args.spp,
        gt_spacing: args.gt_spacing,
        progress: std::io::stderr().is_terminal(),
        overwrite: args.overwrite,
    };
    let r = generate(&args.out, &opts)?;
    println!(
        "wrote {} ({} views, {} gt points) to {} in {:.2} s (render {:.2} s, gt {:.2} s)",
        args.kind.name(),
        r.views,
        r.gt_points,
        args.out.display(),
        r.total_s,
        r.render_s,
        r.gt_s
    );
    Ok(())
}
