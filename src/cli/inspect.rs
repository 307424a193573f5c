//! `alphasurf inspect DATASET`: loads a NeRF-synthetic dataset and prints its splits, cameras,
//! estimated object bounds, warnings, and the load time and memory.

use crate::data::{inspect::inspect, Dataset, LoadOptions};
use std::path::PathBuf;

/// Arguments of `inspect`.
#[derive(clap::Args, Debug)]
pub struct InspectArgs {
    /// Dataset directory (with transforms_{train,val,test}.json).
    pub dataset: PathBuf,
    /// Box-downscale the images by this factor.
    #[arg(long, default_value_t = 1)]
    pub downscale: u32,
}

/// Runs `inspect`.
pub fn run(args: &InspectArgs) -> anyhow::Result<()> {
    let opts = LoadOptions {
        downscale: args.downscale,
        ..LoadOptions::default()
    };
    let ds = Dataset::load(&args.dataset, &opts)?;
    let r = ds.report;
    println!("dataset {}", ds.root.display());
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
        println!("note: no transforms_val.json; val uses the test split");
    }
    print!("{}", inspect(&ds));
    Ok(())
}
