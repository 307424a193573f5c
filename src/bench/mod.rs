//! Benchmarks behind `alphasurf bench …`: they print figures (and a JSON line with --json).

pub mod accuracy;
pub mod cubic;
pub mod dda;
pub mod plenoxels;
mod stage1;
pub mod surface;
pub mod time_vs_error;

/// Refuse a benchmark whose every unit of work failed (`failed` of `total` sweep points or
/// scenes): its table and files are written, but exit code 0 would read as a result.
pub fn ensure_any_succeeded(what: &str, failed: usize, total: usize) -> anyhow::Result<()> {
    anyhow::ensure!(
        failed < total || total == 0,
        "every {what} failed ({failed} of {total}); the errors are above and in the table"
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_bench_fails_only_when_every_unit_failed() {
        super::ensure_any_succeeded("point", 2, 3).unwrap();
        super::ensure_any_succeeded("point", 0, 0).unwrap();
        let e = super::ensure_any_succeeded("point", 3, 3).unwrap_err();
        assert!(e.to_string().contains("every point failed (3 of 3)"), "{e}");
    }
}
