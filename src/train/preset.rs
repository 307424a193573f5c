//! The named choices behind a training configuration: the size preset (`--preset`) and the data
//! category (`--category`). Their names on the command line, in checkpoints and in metrics.json
//! are the lowercase variant names, as they were when these were strings.

use serde::{Deserialize, Serialize};
use std::fmt;

/// A training schedule's size.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Preset {
    /// The paper's: stage 1 svox2's synthetic schedule (256³ → 512³, 128k steps of 5000 rays),
    /// stage 2 50k steps of 5000 rays.
    Paper,
    /// Sized for a few CPU cores: stage 1 64³ → 128³ in 3000 steps of 4096 rays (more on finer
    /// grids: 8192 at 256³, 16384 at 512³), stage 2 1500 steps of 4096 rays (every schedule
    /// scaled alike).
    Fast,
    /// A stage-1 grid brought in from an svox2 checkpoint by `import`: recorded in its
    /// configuration, never chosen on the command line.
    #[value(skip)]
    Imported,
}

impl Preset {
    /// The name on the command line and in saved configurations.
    pub fn name(self) -> &'static str {
        match self {
            Preset::Paper => "paper",
            Preset::Fast => "fast",
            Preset::Imported => "imported",
        }
    }
}

impl fmt::Display for Preset {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.pad(self.name())
    }
}

/// The data category whose stage-2 hyper-parameters the supplement gives (method.md §3.4–3.5).
/// Ordered as listed.
#[derive(
    clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Category {
    /// Thin structures (the synthetic set-up).
    Thin,
    /// Semi-transparent objects.
    Translucent,
    /// Opaque objects: the paper's synthetic set-up (thin's under `--preset paper`; `fast` starts
    /// σα lower and fades unseen surfaces faster, and `extract` trims nothing by default).
    Synthetic,
    /// Real captures.
    Real,
    /// DTU scans.
    Dtu,
}

impl Category {
    /// The name on the command line and in saved configurations.
    pub fn name(self) -> &'static str {
        match self {
            Category::Thin => "thin",
            Category::Translucent => "translucent",
            Category::Synthetic => "synthetic",
            Category::Real => "real",
            Category::Dtu => "dtu",
        }
    }
}

impl fmt::Display for Category {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.pad(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::ValueEnum;

    #[test]
    fn names_agree_on_the_command_line_and_in_json() {
        for p in Preset::value_variants() {
            assert_eq!(p.to_possible_value().unwrap().get_name(), p.name());
            assert_eq!(serde_json::to_value(p).unwrap(), p.name());
        }
        for c in Category::value_variants() {
            assert_eq!(c.to_possible_value().unwrap().get_name(), c.name());
            assert_eq!(serde_json::to_value(c).unwrap(), c.name());
        }
        assert_eq!(
            serde_json::from_str::<Preset>("\"imported\"").unwrap(),
            Preset::Imported
        );
        assert!(Preset::from_str("imported", false).is_err());
        assert!(serde_json::from_str::<Category>("\"Thin\"").is_err());
    }

    /// The `config` of a stage-1 run's metrics.json written while presets were strings (fast,
    /// 64³ → 128³).
    const STAGE1_SAVED: &str = r#"{
        "batch":4096,
        "beta":0.949999988079071,
        "checkpoint_every":500,
        "eps":9.99999993922529e-09,
        "init_sigma":0.10000000149011612,
        "iters":3000,
        "lr_sh":{"delay_mult":1.0,"delay_steps":0,"init":0.009999999776482582,"last":0.0010000000474974513,"max_steps":3000},
        "lr_sigma":{"delay_mult":0.009999999776482582,"delay_steps":300,"init":30.0,"last":0.5,"max_steps":3000},
        "preset":"fast",
        "prune_pixel_stride":2,
        "prune_stop_thresh":0.20000000298023224,
        "prune_weight":0.0005000000237487257,
        "res":64,
        "seed":0,
        "stop_thresh":9.999999747378752e-05,
        "tv_fraction":0.009999999776482582,
        "tv_sh":0.0010000000474974513,
        "tv_sigma":9.999999747378752e-06,
        "tv_until_upsample":false,
        "upsample":[[1000,128]]
    }"#;

    /// The `config` of a stage-2 run's metrics.json written then (fast, thin).
    const STAGE2_SAVED: &str = r#"{
        "a":{"end":2.0,"start":5.0,"steps":300},
        "alpha_fraction":0.30000001192092896,
        "batch":4096,
        "beta":0.949999988079071,
        "category":"thin",
        "checkpoint_every":500,
        "delta_fraction":1.0,
        "eps":9.99999993922529e-09,
        "init":{"alpha_init_scale":0.004999999888241291,"density_levels":[10.0,30.0,50.0,70.0,90.0]},
        "iters":1500,
        "lambda_alpha":9.999999974752427e-07,
        "lambda_c":9.999999974752427e-07,
        "lambda_c_until":300,
        "lambda_delta":0.0010000000474974513,
        "lambda_h":9.999999747378752e-05,
        "lambda_n1":{"end":9.999999974752427e-07,"start":9.999999974752427e-07,"steps":0},
        "lambda_n2":0.0,
        "lambda_tv_alpha":9.999999747378752e-06,
        "lr_delta":{"delay_mult":0.009999999776482582,"delay_steps":750,"init":9.999999747378752e-06,"last":9.999999747378752e-06,"max_steps":1500},
        "lr_opacity":{"delay_mult":0.009999999776482582,"delay_steps":750,"init":0.009999999776482582,"last":0.0010000000474974513,"max_steps":1500},
        "lr_sh":{"delay_mult":1.0,"delay_steps":0,"init":0.0010000000474974513,"last":0.0010000000474974513,"max_steps":1},
        "normal_fraction":0.10000000149011612,
        "preset":"fast",
        "prune_alpha":0.10000000149011612,
        "seed":0,
        "stop_thresh":9.999999747378752e-05,
        "tv_alpha_fraction":0.009999999776482582
    }"#;

    #[test]
    fn configurations_saved_with_string_names_still_load() {
        use crate::train::{PlenoxelsConfig, SurfaceConfig};
        let s1: PlenoxelsConfig = serde_json::from_str(STAGE1_SAVED).unwrap();
        assert_eq!(s1.preset, Preset::Fast);
        // Written before the background's spheres had a TV: none.
        assert_eq!(s1.tv_background, 0.0);
        assert_eq!(s1.sparsity, 0.0);
        let again: serde_json::Value = serde_json::to_value(&s1).unwrap();
        assert_eq!(again["preset"], "fast");
        let imported = STAGE1_SAVED.replace(r#""preset":"fast""#, r#""preset":"imported""#);
        let s1: PlenoxelsConfig = serde_json::from_str(&imported).unwrap();
        assert_eq!(s1.preset, Preset::Imported);
        let s2: SurfaceConfig = serde_json::from_str(STAGE2_SAVED).unwrap();
        assert_eq!((s2.preset, s2.category), (Preset::Fast, Category::Thin));
        // Written before batches could be focused: uniform.
        assert_eq!(s2.ray_focus, 0.0);
        let again: serde_json::Value = serde_json::to_value(&s2).unwrap();
        assert_eq!(
            (&again["preset"], &again["category"]),
            (&"fast".into(), &"thin".into())
        );
        let unknown = STAGE2_SAVED.replace(r#""category":"thin""#, r#""category":"shiny""#);
        assert!(serde_json::from_str::<SurfaceConfig>(&unknown).is_err());
    }
}
