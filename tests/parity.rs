//! Every registered kernel against its CPU twin on lavapipe (the rows of `check-kernels`).

use alphasurf::check::CHECKS;
use alphasurf::gpu::test_gpu;

#[test]
fn every_kernel_matches_its_cpu_twin() {
    let gpu = test_gpu();
    let mut failures = Vec::new();
    for seed in [1u64, 2] {
        for (name, check) in CHECKS {
            let row = check(gpu, seed).unwrap_or_else(|e| panic!("{name}: {e:#}"));
            if !row.pass {
                failures.push(format!("{row:?}"));
            }
        }
    }
    assert!(
        failures.is_empty(),
        "parity failures:\n{}",
        failures.join("\n")
    );
    let msgs = gpu.validation_messages();
    assert!(msgs.is_empty(), "validation messages: {msgs:#?}");
}
