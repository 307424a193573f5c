//! Every registered kernel against its CPU twin on lavapipe (the rows of `check-kernels`): one
//! test per row, named after it (`cargo test --test kernels parity::surface_fwd` runs that row
//! alone), and a test that no registered row is left without one.

use alphasurf::check::rows;
use alphasurf::gpu::test_gpu;

/// Runs the row `name` of `CHECKS` with seeds 1 and 2; fails naming the seed and the row.
fn row_matches(name: &str) {
    let gpu = test_gpu();
    let (_, check) = rows()
        .into_iter()
        .find(|(n, _)| *n == name)
        .unwrap_or_else(|| panic!("{name} is not a registered parity row"));
    let mut failures = Vec::new();
    for seed in [1u64, 2] {
        let row = check(gpu, seed).unwrap_or_else(|e| panic!("{name} seed {seed}: {e:#}"));
        if !row.pass {
            failures.push(format!("seed {seed}: {row:?}"));
        }
    }
    assert!(
        failures.is_empty(),
        "{name} parity failures:\n{}",
        failures.join("\n")
    );
    let msgs = gpu.validation_messages();
    assert!(msgs.is_empty(), "validation messages: {msgs:#?}");
}

/// One `#[test]` per row name, plus the list of the names the tests cover.
macro_rules! rows {
    ($($row:ident),* $(,)?) => {
        $(
            #[test]
            fn $row() {
                row_matches(stringify!($row));
            }
        )*
        const TESTED: &[&str] = &[$(stringify!($row)),*];
    };
}

rows!(
    background_msi_eval,
    background_spheres_step,
    background_step,
    cubic_solve,
    dda_walk,
    extract_points,
    fill_pattern,
    loss_sum,
    occupancy,
    optim_args,
    plenoxel_fwd,
    plenoxel_fwd_spheres,
    plenoxel_train,
    plenoxel_train_spheres,
    plenoxel_weights,
    rmsprop_sparse,
    sample_rays,
    sample_rays_sort,
    sh_eval,
    surface_block_radius,
    surface_blocks,
    surface_delta_tv,
    surface_fwd,
    surface_fwd_spheres,
    surface_faces,
    surface_live_cells,
    surface_normal_reg_cells,
    surface_normal_reg_gather,
    surface_normal_reg_pairs,
    surface_opacity_reg,
    surface_rmsprop,
    surface_train,
    surface_train_spheres,
    trilerp_eval,
    tv,
    tv_spheres,
);

#[test]
fn every_registered_row_has_a_test() {
    let registered: Vec<&str> = rows().iter().map(|(n, _)| *n).collect();
    assert_eq!(
        registered, TESTED,
        "tests/kernels/parity.rs must list every row of check::rows(), in table order"
    );
}
