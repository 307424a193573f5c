//! Reader of the per-step training log `train_log.csv` that both training stages write into their
//! run directory (header `step,mse,psnr_batch,elapsed_s`; see `crate::run::dir::TRAIN_LOG`).

use anyhow::{bail, ensure, Context, Result};
use std::path::Path;

/// One logged step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LogRow {
    /// Steps done.
    pub step: u32,
    /// Batch mean squared error.
    pub mse: f64,
    /// PSNR of `mse`, dB.
    pub psnr: f64,
    /// Seconds since training started.
    pub elapsed_s: f64,
}

/// Parse the text of a training log; the columns are found by name, so extra columns are fine.
pub fn parse(text: &str) -> Result<Vec<LogRow>> {
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    let (_, header) = lines.next().context("empty training log")?;
    let cols: Vec<&str> = header.split(',').map(str::trim).collect();
    let col = |name: &str| {
        cols.iter()
            .position(|c| *c == name)
            .with_context(|| format!("training log header {header:?} has no column {name}"))
    };
    let (ci, cm, cp, ce) = (
        col("step")?,
        col("mse")?,
        col("psnr_batch")?,
        col("elapsed_s")?,
    );
    let mut rows = Vec::new();
    for (n, line) in lines {
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        if f.len() != cols.len() {
            bail!(
                "training log line {}: {} fields, header has {}",
                n + 1,
                f.len(),
                cols.len()
            );
        }
        let num = |i: usize| -> Result<f64> {
            f[i].parse::<f64>()
                .with_context(|| format!("training log line {}: {:?} is not a number", n + 1, f[i]))
        };
        let step = num(ci)?;
        ensure!(
            step >= 0.0 && step.fract() == 0.0,
            "training log line {}: bad step {step}",
            n + 1
        );
        rows.push(LogRow {
            step: step as u32,
            mse: num(cm)?,
            psnr: num(cp)?,
            elapsed_s: num(ce)?,
        });
    }
    Ok(rows)
}

/// Read a run directory's training log file.
pub fn read(path: &Path) -> Result<Vec<LogRow>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    parse(&text).with_context(|| format!("parsing {}", path.display()))
}

/// Moving average of `v` over a centred window of `k` values (shrunk at the ends), to show the
/// trend of a noisy per-batch curve.
pub fn smooth(v: &[f64], k: usize) -> Vec<f64> {
    let h = k / 2;
    (0..v.len())
        .map(|i| {
            let w = &v[i.saturating_sub(h)..(i + h + 1).min(v.len())];
            w.iter().sum::<f64>() / w.len() as f64
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_by_column_name_and_rejects_garbage() {
        let rows =
            parse("step,mse,psnr_batch,elapsed_s\n1,1e-2,20.0,0.5\n2,5e-3,23.01,1.0\n").unwrap();
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[1].step, 2);
        assert_eq!(rows[0].mse, 1e-2);
        let reordered = parse("elapsed_s,step,psnr_batch,mse,extra\n0.5,7,20,0.01,x\n").unwrap();
        assert_eq!(reordered[0].step, 7);
        assert_eq!(reordered[0].elapsed_s, 0.5);
        assert!(parse("").is_err());
        assert!(parse("step,mse\n1,2\n").is_err());
        assert!(parse("step,mse,psnr_batch,elapsed_s\n1,abc,2,3\n").is_err());
        assert!(parse("step,mse,psnr_batch,elapsed_s\n1,2,3\n").is_err());
        assert!(parse("step,mse,psnr_batch,elapsed_s\n-1,2,3,4\n").is_err());
    }

    #[test]
    fn smoothing_keeps_length_and_constant_input() {
        assert_eq!(smooth(&[2.0; 5], 3), vec![2.0; 5]);
        assert_eq!(smooth(&[0.0, 3.0, 0.0], 3), vec![1.5, 1.0, 1.5]);
        assert!(smooth(&[], 5).is_empty());
    }
}
