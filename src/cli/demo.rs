//! `demo`: the library call and what it prints (the results table, each object group's share,
//! αSurf against the best level).

use crate::pipeline::demo::{demo, first_line, objects_table, table, DemoOptions};
use crate::pipeline::Devices;
use anyhow::Result;

/// Run `demo` and print its table.
pub fn run(opts: &DemoOptions, devices: &mut Devices) -> Result<()> {
    let d = demo(opts, devices)?;
    println!();
    print!("{}", table(&d.rows, false));
    if let Some(t) = d
        .best()
        .zip(d.alphasurf())
        .and_then(|(b, a)| objects_table(b, a, false))
    {
        println!("\nwhere the Chamfer distance comes from (×10⁻², shares add up to it):");
        print!("{t}");
    }
    if let (Some(b), Some(a)) = (
        d.best().and_then(|b| b.chamfer_e2),
        d.alphasurf().and_then(|r| r.chamfer_e2),
    ) {
        println!(
            "αSurf Chamfer vs best Plenoxels level: {:+.1} %",
            100.0 * (a - b) / b
        );
    }
    if let Some(e) = &d.stage2_error {
        println!("stage 2 (αSurf) did not run: {}", first_line(e));
    }
    println!(
        "demo done in {:.1} s: {} ({} figures)",
        d.elapsed_s,
        d.report.display(),
        d.figures
    );
    Ok(())
}
