//! `train`, `render`, `export` and `import`: the library calls and what they print.

use crate::gpu::Gpu;
use crate::pipeline::render::{render, RenderOptions};
use crate::pipeline::svox2::{export, import, ExportOptions, ImportOptions};
use crate::pipeline::train::train;
use crate::pipeline::train_run::Trained;
use crate::pipeline::TrainOptions;
use anyhow::Result;

/// Run `train` and print each stage's test PSNR, counters and summary.
pub fn run_train(opts: &TrainOptions, gpu: Option<&Gpu>) -> Result<()> {
    let outcome = train(opts, gpu)?;
    if let Some(t) = &outcome.stage1 {
        print_trained(t, |m| m.summary());
    }
    if let Some(t) = &outcome.stage2 {
        print_trained(t, |m| m.summary());
    }
    Ok(())
}

fn print_trained<M>(t: &Trained<M>, summary: impl Fn(&M) -> String) {
    match t {
        Trained::Done(m) => print!("{}", summary(m)),
        Trained::AlreadyDone {
            checkpoint,
            step,
            total,
        } => println!(
            "{} is already at step {step} of {total}: nothing to train (pass --iters to extend)",
            checkpoint.display()
        ),
    }
}

/// Run `render` and print the per-view and mean PSNR.
pub fn run_render(opts: &RenderOptions, gpu: Option<&Gpu>) -> Result<()> {
    let r = render(opts, gpu)?;
    for (i, p) in r.psnr.iter().enumerate() {
        println!("{} view {i:>3}: PSNR {p:.2} dB", r.split);
    }
    let n = opts.pixel_samples;
    let samples = if n > 1 {
        format!(" ({n}×{n} rays per pixel)")
    } else {
        String::new()
    };
    println!(
        "mean PSNR {:.2} dB over {} views{samples} -> {}",
        r.mean_psnr,
        r.psnr.len(),
        opts.out.display()
    );
    Ok(())
}

/// Run `export`.
pub fn run_export(opts: &ExportOptions) -> Result<()> {
    let grid = export(opts)?;
    println!(
        "exported {}³ grid ({} vertices) to {}",
        grid.res[0],
        grid.allocated(),
        opts.out.display()
    );
    Ok(())
}

/// Run `import`.
pub fn run_import(opts: &ImportOptions) -> Result<()> {
    let grid = import(opts)?;
    println!(
        "imported {} ({:?} grid, {} vertices) into {}",
        opts.ckpt.display(),
        grid.res,
        grid.allocated(),
        opts.out.display()
    );
    Ok(())
}
