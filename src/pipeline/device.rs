//! The Vulkan device of a command (`--device`, `--backend`): opened once, on first use, and
//! shared by every step of the command, so `--profile` sees all of its kernels.

use crate::backend::Backend;
use crate::gpu::{DeviceKind, Gpu, GpuOptions};
use anyhow::Result;

/// The device `--device` names (`None`: the default one), opened when a step first needs it.
pub struct Devices {
    index: Option<usize>,
    opened: Option<Gpu>,
}

impl Devices {
    /// Nothing is opened yet.
    pub fn new(index: Option<usize>) -> Devices {
        Devices {
            index,
            opened: None,
        }
    }

    /// The Vulkan device, opened now if it is not yet (validation on when
    /// `ALPHASURF_VALIDATION` is set; data moved through staging buffers, as on a discrete GPU,
    /// when `ALPHASURF_FORCE_STAGING` is).
    pub fn gpu(&mut self) -> Result<&Gpu> {
        if self.opened.is_none() {
            self.opened = Some(open(self.index)?);
        }
        Ok(self.opened.as_ref().expect("opened above"))
    }

    /// The device a training, rendering or extraction step should use, or `None` for the CPU
    /// backend. `auto` takes the Vulkan device unless it is a CPU implementation (lavapipe) or
    /// missing.
    pub fn for_backend(&mut self, kind: Backend) -> Result<Option<&Gpu>> {
        match kind {
            Backend::Cpu => Ok(None),
            Backend::Vulkan => self.gpu().map(Some),
            Backend::Auto => {
                if self.opened.is_none() {
                    match open(self.index) {
                        Ok(gpu) if gpu.info().kind != DeviceKind::Cpu => self.opened = Some(gpu),
                        Ok(gpu) => {
                            eprintln!(
                                "backend auto: {} is a CPU implementation of Vulkan; using the \
                                 CPU backend, which is faster there (--backend vulkan forces the \
                                 device)",
                                gpu.info().name
                            );
                            return Ok(None);
                        }
                        Err(e) => {
                            eprintln!(
                                "backend auto: no usable Vulkan device ({e:#}); using the CPU \
                                 backend"
                            );
                            return Ok(None);
                        }
                    }
                }
                Ok(self
                    .opened
                    .as_ref()
                    .filter(|g| g.info().kind != DeviceKind::Cpu))
            }
        }
    }

    /// The device if a step opened and kept it (for `--profile`).
    pub fn opened(&self) -> Option<&Gpu> {
        self.opened.as_ref()
    }
}

fn open(index: Option<usize>) -> Result<Gpu> {
    Gpu::new(&GpuOptions {
        device: index,
        validation: std::env::var_os("ALPHASURF_VALIDATION").is_some(),
        force_staging: std::env::var_os("ALPHASURF_FORCE_STAGING").is_some(),
    })
}
