//! `cargo run --release --example convert_scene -- FORMAT SRC DST`: converts the NeRF-synthetic
//! dataset SRC (e.g. from `alphasurf make-scene`) into FORMAT (colmap-text, colmap-binary, idr,
//! instant-ngp, instant-ngp-distorted: images as a phone's OPENCV lens would have imaged them,
//! or llff) at DST, with exact poses (see convert.rs).

#[path = "convert.rs"]
mod convert;

use alphasurf::data::distortion::Distortion;
use convert::Target;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage =
        "usage: convert_scene colmap-text|colmap-binary|idr|instant-ngp|instant-ngp-distorted|llff SRC DST";
    anyhow::ensure!(args.len() == 3, "{usage}");
    let target = match args[0].as_str() {
        "colmap-text" => Target::ColmapText,
        "colmap-binary" => Target::ColmapBinary,
        "idr" => Target::Idr,
        "instant-ngp" => Target::InstantNgp(Distortion::None),
        "instant-ngp-distorted" => Target::InstantNgp(convert::PHONE_LENS),
        "llff" => Target::Llff,
        f => anyhow::bail!("unknown format '{f}'; {usage}"),
    };
    convert::convert(args[1].as_ref(), args[2].as_ref(), target)?;
    println!("wrote {} ({})", args[2], args[0]);
    Ok(())
}
