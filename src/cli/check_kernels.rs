//! `alphasurf check-kernels`: every kernel on the Vulkan device against its CPU twin.

use crate::check::{rows, CheckRow};
use crate::gpu::Gpu;
use anyhow::Result;

/// Arguments of `check-kernels`.
#[derive(clap::Args, Debug)]
pub struct CheckKernelsArgs {
    /// Seed of the random cases.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Run only the kernels whose name contains this text.
    #[arg(long)]
    pub only: Option<String>,
    /// Print one JSON object (all rows and an overall `pass`) as the last line.
    #[arg(long)]
    pub json: bool,
}

/// Run the checks, print the table; returns whether all passed.
pub fn run(gpu: &Gpu, args: &CheckKernelsArgs) -> Result<bool> {
    let checks = rows();
    if let Some(only) = &args.only {
        let names: Vec<&str> = checks.iter().map(|c| c.0).collect();
        anyhow::ensure!(
            names.iter().any(|n| n.contains(only.as_str())),
            "--only {only:?} matches no kernel; the kernels are {}",
            names.join(", ")
        );
    }
    println!("device: {} ({})", gpu.info().name, gpu.info().driver);
    println!(
        "{:<16} {:>8} {:>11} {:>11} {:<28} {:<5} note",
        "kernel", "cases", "max abs", "max rel", "tolerance", "pass"
    );
    let mut rows: Vec<CheckRow> = Vec::new();
    for (name, f) in checks {
        if args.only.as_deref().is_some_and(|o| !name.contains(o)) {
            continue;
        }
        let row = f(gpu, args.seed)?;
        println!(
            "{:<16} {:>8} {:>11.3e} {:>11.3e} {:<28} {:<5} {}",
            row.kernel,
            row.cases,
            row.max_abs,
            row.max_rel,
            row.tolerance,
            if row.pass { "ok" } else { "FAIL" },
            row.note
        );
        rows.push(row);
    }
    let messages = gpu.validation_messages();
    for m in &messages {
        println!("validation: {m}");
    }
    let pass = !rows.is_empty() && rows.iter().all(|r| r.pass) && messages.is_empty();
    println!(
        "{}",
        if pass {
            "all kernels match their CPU twins"
        } else {
            "PARITY FAILURES"
        }
    );
    if args.json {
        println!(
            "{}",
            serde_json::json!({ "device": gpu.info().name, "rows": rows, "pass": pass })
        );
    }
    Ok(pass)
}
