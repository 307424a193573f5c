//! The kernel registry: each kernel `glsl/<name>.comp` (a variant of the build's
//! [`Kernel`](crate::kernels::Kernel)) named with its CPU twin, `cpu::<name>` or an item of the
//! module `cpu::<name>`, and its parity rows. [`entry`] matches on every kernel, so a kernel added
//! to `glsl/` without an entry fails to compile, a twin path the compiler cannot resolve fails
//! to compile, and the tests below fail when a kernel's header names another twin.

use super::{
    background_msi, cubic_solve, dda_walk, extract_points, fill_pattern, loss_sum, plenoxel,
    sample_rays, sh_eval, surface_blocks, surface_faces, surface_fwd, surface_reg, surface_train,
    trilerp_eval, CheckFn,
};
use crate::kernels::Kernel;

/// A kernel's CPU twin and its parity rows (name, check), at least one.
pub struct Entry {
    /// Path of the twin (`crate::cpu::...`), as written in the registry.
    pub twin: &'static str,
    pub rows: &'static [(&'static str, CheckFn)],
}

/// `twin!(path; row => check, ...)`: the entry of a kernel whose twin is `path` (resolved by
/// the compiler) and whose parity rows are the given checks.
macro_rules! twin {
    ($twin:path; $($row:literal => $check:expr),+ $(,)?) => {{
        let _ = $twin;
        Entry {
            twin: stringify!($twin),
            rows: &[$(($row, $check as CheckFn)),+],
        }
    }};
}

/// The registry entry of `kernel`.
pub fn entry(kernel: Kernel) -> Entry {
    match kernel {
        Kernel::background_msi_eval => {
            twin!(crate::cpu::background_msi_eval;
            "background_msi_eval" => background_msi::check)
        }
        Kernel::background_spheres_step => {
            twin!(crate::cpu::background_spheres_step::background_spheres_step;
            "background_spheres_step" => background_msi::check_step)
        }
        Kernel::background_step => twin!(crate::cpu::background_step::background_step;
            "background_step" => plenoxel::check_background_step),
        Kernel::cubic_solve => twin!(crate::cpu::cubic_solve::cubic_solve;
            "cubic_solve" => cubic_solve::check),
        Kernel::dda_walk => twin!(crate::cpu::dda_walk; "dda_walk" => dda_walk::check),
        Kernel::extract_points => twin!(crate::cpu::extract_points::extract_points;
            "extract_points" => extract_points::check),
        Kernel::fill_pattern => {
            twin!(crate::cpu::fill_pattern; "fill_pattern" => fill_pattern::check)
        }
        Kernel::loss_sum => twin!(crate::cpu::loss_sum; "loss_sum" => loss_sum::check),
        Kernel::occupancy => twin!(crate::cpu::occupancy::occupancy;
            "occupancy" => plenoxel::check_occupancy),
        Kernel::optim_args => twin!(crate::cpu::optim_args::optim_args;
            "optim_args" => plenoxel::check_optim_args),
        Kernel::plenoxel_fwd => twin!(crate::cpu::plenoxel_fwd::render;
            "plenoxel_fwd" => plenoxel::check_fwd,
            "plenoxel_fwd_spheres" => plenoxel::check_fwd_spheres),
        Kernel::plenoxel_train => twin!(crate::cpu::plenoxel_train::train;
            "plenoxel_train" => plenoxel::check_train,
            "plenoxel_train_spheres" => plenoxel::check_train_spheres),
        Kernel::plenoxel_weights => twin!(crate::cpu::plenoxel_weights::max_weights;
            "plenoxel_weights" => plenoxel::check_weights),
        Kernel::rmsprop_sparse => twin!(crate::cpu::rmsprop_sparse;
            "rmsprop_sparse" => plenoxel::check_rmsprop),
        Kernel::sample_rays => twin!(crate::cpu::sample_rays::sample_rays;
            "sample_rays" => sample_rays::check),
        Kernel::sample_rays_sort => twin!(crate::cpu::sample_rays_sort;
            "sample_rays_sort" => sample_rays::check_sort),
        Kernel::sh_eval => twin!(crate::cpu::sh_eval; "sh_eval" => sh_eval::check),
        Kernel::surface_block_radius => twin!(crate::cpu::surface_block_radius;
            "surface_block_radius" => surface_blocks::check_radius),
        Kernel::surface_blocks => twin!(crate::cpu::surface_blocks::build_blocks;
            "surface_blocks" => surface_blocks::check),
        Kernel::surface_delta_tv => twin!(crate::cpu::surface_delta_tv::delta_tv;
            "surface_delta_tv" => surface_reg::check_delta_tv),
        Kernel::surface_fwd => twin!(crate::cpu::surface_fwd::render;
            "surface_fwd" => surface_fwd::check,
            "surface_fwd_spheres" => surface_fwd::check_spheres,
            "surface_faces" => surface_faces::check),
        Kernel::surface_live_cells => twin!(crate::cpu::surface_live_cells::surface_live_cells;
            "surface_live_cells" => surface_blocks::check_live),
        Kernel::surface_normal_reg_cells => {
            twin!(crate::cpu::surface_normal_reg_cells::normal_cells;
            "surface_normal_reg_cells" => surface_reg::check_normal_cells)
        }
        Kernel::surface_normal_reg_gather => {
            twin!(crate::cpu::surface_normal_reg_gather::normal_gather;
            "surface_normal_reg_gather" => surface_reg::check_normal_gather)
        }
        Kernel::surface_normal_reg_pairs => {
            twin!(crate::cpu::surface_normal_reg_pairs::normal_pairs;
            "surface_normal_reg_pairs" => surface_reg::check_normal_pairs)
        }
        Kernel::surface_opacity_reg => twin!(crate::cpu::surface_opacity_reg::surface_opacity_reg;
            "surface_opacity_reg" => surface_reg::check_opacity_reg),
        Kernel::surface_rmsprop => twin!(crate::cpu::surface_rmsprop;
            "surface_rmsprop" => surface_reg::check_rmsprop),
        Kernel::surface_train => twin!(crate::cpu::surface_train::train;
            "surface_train" => surface_train::check,
            "surface_train_spheres" => surface_train::check_spheres),
        Kernel::trilerp_eval => {
            twin!(crate::cpu::trilerp_eval; "trilerp_eval" => trilerp_eval::check)
        }
        Kernel::tv => twin!(crate::cpu::tv; "tv" => plenoxel::check_tv,
            "tv_spheres" => background_msi::check_tv),
    }
}

/// Every parity row, kernel by kernel in file-name order: what `check-kernels` runs and
/// `tests/kernels/parity.rs` asserts.
pub fn rows() -> Vec<(&'static str, CheckFn)> {
    Kernel::ALL
        .iter()
        .flat_map(|&k| entry(k).rows.iter().copied())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every kernel's twin lives at `cpu::<kernel>` or in the module `cpu::<kernel>`, and the
    /// kernel's header names that twin (`CPU twin: `cpu::...``).
    #[test]
    fn every_kernel_names_its_registered_twin() {
        let mut wrong = Vec::new();
        for k in Kernel::ALL {
            let name = k.info().name;
            let twin = entry(k).twin.replace(' ', "");
            let path = twin.trim_start_matches("crate::");
            if path != format!("cpu::{name}") && !path.starts_with(&format!("cpu::{name}::")) {
                wrong.push(format!("{name}: twin {path} is not cpu::{name}[::…]"));
            }
            let file = format!("{}/glsl/{name}.comp", env!("CARGO_MANIFEST_DIR"));
            let source = std::fs::read_to_string(&file).unwrap();
            // The opening comment, after the `#version` line.
            let header: String = source
                .lines()
                .skip_while(|l| !l.starts_with("//"))
                .take_while(|l| l.starts_with("//"))
                .map(|l| l.trim_start_matches('/').trim())
                .collect::<Vec<_>>()
                .join(" ");
            if !header.contains(&format!("CPU twin: `{path}`")) {
                wrong.push(format!(
                    "glsl/{name}.comp: header lacks \"CPU twin: `{path}`\""
                ));
            }
        }
        assert!(wrong.is_empty(), "{}", wrong.join("\n"));
    }

    /// Every kernel has a parity row named after it, and no two rows share a name.
    #[test]
    fn every_kernel_has_its_parity_row() {
        let rows = rows();
        let mut names: Vec<&str> = rows.iter().map(|r| r.0).collect();
        for k in Kernel::ALL {
            let own = entry(k).rows.iter().any(|r| r.0 == k.info().name);
            assert!(own, "{}: no parity row named after it", k.info().name);
        }
        names.sort();
        names.dedup();
        assert_eq!(names.len(), rows.len(), "two parity rows share a name");
    }
}
