//! Vulkan compute runtime: instance and device choice (`device`), the context with its allocator
//! and pipelines (`context`), RAII buffers addressed by device address (`buffer`), batched
//! submission with timestamp queries (`batch`), per-kernel profiles (`profile`), and what the Vulkan
//! backends share: the grid's links and optimised arrays (`grid_buffers`), per-batch ray buffers (`ray_buffers`), per-step results in a ring of
//! host-visible slots (`readback`) with the step's loss summed on the device (`loss_sum`), the
//! steps submitted and not yet read (`in_flight`), the `optim_args` and `tv` recordings (`optim_args`, `tv`), the
//! host time of a training step by phase (`step_times`), the training views and the batches
//! sampled from them (`train_views`).

mod background_step;
mod batch;
mod buffer;
mod context;
mod device;
mod frame;
mod grid_buffers;
mod in_flight;
mod instance;
mod loss_sum;
mod optim_args;
mod profile;
mod ray_buffers;
mod readback;
mod step_queue;
mod step_times;
mod train_views;
mod tv;

pub use background_step::{record_background_step, record_sphere_tv, SphereBuffers};
pub use batch::{Batch, BatchTimes, InFlight};
pub use buffer::{address_words, GpuBuffer};
pub use context::{list_devices, Gpu, GpuOptions};
pub use device::{pick_default, DeviceInfo, DeviceKind};
pub use grid_buffers::GridBuffers;
pub use in_flight::{StepMeta, StepsInFlight, MAX_IN_FLIGHT};
pub use loss_sum::record_loss_sum;
pub use optim_args::record_optim_args;
pub use profile::Profile;
pub use ray_buffers::RayBuffers;
pub use readback::{Readback, STEP_SLOTS};
pub use step_queue::{BatchRays, SlotFigures, StepQueue};
pub use step_times::{timed, Phase, PhaseClock, StepTimes, StepTiming};
pub use train_views::{record_sort_runs, KeyDraw, SampledAt, TrainRays, TrainViewBuffers};
pub use tv::record_tv;

use std::sync::OnceLock;

/// The shared context for tests: device from `ALPHASURF_DEVICE` (else the default choice) with the
/// validation layer on when installed. Panics — failing the test, never skipping it — when no
/// usable Vulkan device exists, or when `CI` is set and the validation layer is missing.
pub fn test_gpu() -> &'static Gpu {
    static GPU: OnceLock<Gpu> = OnceLock::new();
    GPU.get_or_init(|| {
        let device = std::env::var("ALPHASURF_DEVICE")
            .ok()
            .map(|s| s.parse().expect("ALPHASURF_DEVICE must be a device index"));
        let gpu = Gpu::new(&GpuOptions {
            device,
            validation: true,
            force_staging: false,
        })
        .unwrap_or_else(|e| panic!("tests need a Vulkan device (lavapipe in CI): {e:#}"));
        if std::env::var_os("CI").is_some() {
            assert!(
                gpu.validation_active(),
                "CI must run the tests under VK_LAYER_KHRONOS_validation (vulkan-validationlayers)"
            );
        }
        gpu
    })
}
