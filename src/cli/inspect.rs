//! `alphasurf inspect DATASET`: loads a dataset (NeRF-synthetic, COLMAP or IDR) and prints its
//! layout, splits, cameras, scene box, estimated object bounds, warnings, and the load time and
//! memory.

use crate::data::{inspect::inspect, Dataset, LoadOptions, SceneBox};
use std::path::PathBuf;

/// Arguments of `inspect`.
#[derive(clap::Args, Debug)]
pub struct InspectArgs {
    /// Dataset directory (NeRF-synthetic, COLMAP or IDR layout; see the README).
    pub dataset: PathBuf,
    /// Box-downscale the images by this factor.
    #[arg(long, default_value_t = 1)]
    pub downscale: u32,
    /// World → scaled-world factor; the grid box [-1, 1]^3 then covers [-1/scale, 1/scale]^3
    /// (default: the layout's box; NeRF-synthetic: 2/3).
    #[arg(long)]
    pub scale: Option<f32>,
}

/// Runs `inspect`.
pub fn run(args: &InspectArgs) -> anyhow::Result<()> {
    if let Some(scale) = args.scale.filter(|s| !(*s > 0.0 && s.is_finite())) {
        anyhow::bail!("--scale must be positive, got {scale}");
    }
    let opts = LoadOptions {
        downscale: args.downscale,
        scene: args.scale.map(|scale| SceneBox {
            scale,
            ..SceneBox::default()
        }),
        ..Default::default()
    };
    let ds = Dataset::load(&args.dataset, &opts)?;
    let r = ds.report;
    println!("dataset {} ({})", ds.root.display(), ds.layout);
    println!(
        "loaded {} images in {:.3} s; pixels held {:.1} MiB (8-bit RGBA); peak RSS {}",
        r.n_images,
        r.seconds,
        r.image_bytes as f64 / (1u64 << 20) as f64,
        r.peak_rss_bytes.map_or("unknown".into(), |b| format!(
            "{:.1} MiB",
            b as f64 / (1u64 << 20) as f64
        ))
    );
    if ds.val_split.is_none() {
        println!("note: no validation split; val uses the test split");
    }
    print!("{}", inspect(&ds));
    Ok(())
}
