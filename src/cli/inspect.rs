//! `alphasurf inspect DATASET`: loads a dataset (NeRF-synthetic, instant-ngp / nerfstudio, COLMAP
//! or IDR) and prints its layout, splits and how they were made, cameras, scene box, the
//! foreground box found from the cameras, estimated object bounds, warnings, and the load time and
//! memory.

use crate::data::ndc::Space;
use crate::data::{inspect::inspect, Aabb, Dataset, LoadOptions, SceneBox};
use std::path::PathBuf;

/// Arguments of `inspect`.
#[derive(clap::Args, Debug)]
pub struct InspectArgs {
    /// Dataset directory (NeRF-synthetic, instant-ngp / nerfstudio, COLMAP or IDR layout; see
    /// docs/datasets.md).
    pub dataset: PathBuf,
    /// Box-downscale the images by this factor.
    #[arg(long, default_value_t = 1)]
    pub downscale: u32,
    /// World → scaled-world factor; the grid box [-1, 1]^3 then covers [-1/scale, 1/scale]^3
    /// (default: the layout's box; NeRF-synthetic: 2/3).
    #[arg(long, conflicts_with = "scene_box")]
    pub scale: Option<f32>,
    /// The scene box in dataset units, `xmin,ymin,zmin,xmax,ymax,zmax`, as `train --box` takes
    /// it: the grid is the cube around it.
    #[arg(
        long = "box",
        value_name = "XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    pub scene_box: Option<Vec<f32>>,
    /// Where the grid lies, as `train --space` takes it: `auto` says whether a forward-facing
    /// capture gets NDC and why.
    #[arg(long, value_enum, default_value_t = Space::Auto, conflicts_with_all = ["scene_box", "scale"])]
    pub space: Space,
}

/// Runs `inspect`.
pub fn run(args: &InspectArgs) -> anyhow::Result<()> {
    if let Some(scale) = args.scale.filter(|s| !(*s > 0.0 && s.is_finite())) {
        anyhow::bail!("--scale must be positive, got {scale}");
    }
    let given = args
        .scene_box
        .as_deref()
        .map(|v| Aabb::from_values("--box", v))
        .transpose()?;
    let opts = LoadOptions {
        downscale: args.downscale,
        scene: given
            .map(|b| b.scene_box())
            .or(args.scale.map(|scale| SceneBox {
                scale,
                ..SceneBox::default()
            })),
        space: args.space,
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
