//! Where the kernels run (`--backend`): the GLSL kernels on the Vulkan device or their CPU twins.
//! Its names on the command line and in reports are the lowercase variant names.

use serde::{Deserialize, Serialize};
use std::fmt;

/// Where the kernels run.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Backend {
    /// Vulkan on a GPU; the CPU twins when the only Vulkan device is a CPU implementation
    /// (lavapipe), where they are faster.
    Auto,
    /// GLSL kernels on the Vulkan device (`--device`).
    Vulkan,
    /// Their CPU twins (rayon).
    Cpu,
}

impl Backend {
    /// The name on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Backend::Auto => "auto",
            Backend::Vulkan => "vulkan",
            Backend::Cpu => "cpu",
        }
    }
}

impl fmt::Display for Backend {
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
        for b in Backend::value_variants() {
            assert_eq!(b.to_possible_value().unwrap().get_name(), b.name());
            assert_eq!(serde_json::to_value(b).unwrap(), b.name());
            assert_eq!(Backend::from_str(b.name(), false).unwrap(), *b);
        }
    }
}
