//! The training views on the device, uploaded once per run: every view's RGBA8 image (a u32 per
//! pixel) and camera, and the buffers `sample_rays` draws each training batch into (rays, targets
//! and the sorted pixel keys, in device-local memory), so a step neither samples nor uploads on
//! the host. On a CPU implementation of Vulkan (lavapipe) the keys are the exception: see
//! [`KeyDraw`].

use super::DeviceKind;
use super::{Batch, Gpu, GpuBuffer};
use crate::abi::buffers::SampleCamera;
use crate::abi::consts::{SAMPLE_SORT_RAYS, SAMPLE_SORT_SIDE};
use crate::abi::rays::{sorted_keys, NdcProjection, SampleSet, SampledRays};
use crate::kernels::{sample_rays, sample_rays_sort};
use anyhow::{ensure, Result};

// glsl/sample_rays_sort.comp's register passes cover log2(SAMPLE_SORT_SIDE) = 6 bits, and
// glsl/sample_rays.comp reads a camera as 8 aligned 64-bit words.
const _: () = assert!(SAMPLE_SORT_SIDE == 64 && std::mem::size_of::<SampleCamera>() == 64);

/// Where a batch's sorted keys are drawn; its rays and targets are always written by
/// `sample_rays` pass 1.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KeyDraw {
    /// `sample_rays` pass 0 and `sample_rays_sort` on the device.
    Device,
    /// The host draw (`abi::rays::sorted_keys`, the same keys bit for bit), written
    /// into the batch in its command stream. The default on a CPU device: there a workgroup runs
    /// on one thread, so the sort's single workgroup per run costs several times the host's sort
    /// (docs/results.md, "Training batches drawn on the device"), and the host is the device's
    /// processor anyway.
    Host,
}

impl KeyDraw {
    /// The default for a device of `kind`.
    pub fn for_device(kind: DeviceKind) -> KeyDraw {
        match kind {
            DeviceKind::Cpu => KeyDraw::Host,
            _ => KeyDraw::Device,
        }
    }
}

/// Keys per in-stream update (`Batch::update` takes at most 65536 bytes).
const UPDATE_KEYS: usize = 65536 / 8;

/// Device addresses of a recorded batch: rays (6 floats each), targets (3 floats each) and
/// per-ray importance weights (0: the set has no focus, every weight is 1).
#[derive(Clone, Copy, Debug)]
pub struct SampledAt {
    pub rays: u64,
    pub targets: u64,
    pub weights: u64,
}

/// One set of training views on the device and the batch buffers.
pub struct TrainViewBuffers {
    /// The id of the set uploaded (`data::TrainViews::id`).
    id: u64,
    pixels: GpuBuffer,
    cams: GpuBuffer,
    /// The set's focus pixels (one unread element when it has none) and threshold.
    focus: GpuBuffer,
    n_focus: u32,
    focus_threshold: u32,
    /// Importance weights of a focus pixel and of any other (`Focus::weights`).
    focus_weights: (f32, f32),
    /// The set's NDC map (`SampleSet::ndc`).
    ndc: Option<NdcProjection>,
    width: u32,
    height: u32,
    n_pixels: u64,
    key_bits: u32,
    /// Where the keys are drawn.
    pub key_draw: KeyDraw,
    /// Batch buffers and the rays they hold, allocated by the first batch.
    batch: Option<BatchBuffers>,
}

struct BatchBuffers {
    capacity: usize,
    rays: GpuBuffer,
    targets: GpuBuffer,
    keys: GpuBuffer,
    /// Per-ray importance weights (written only for a set with a focus).
    weights: GpuBuffer,
    /// The batch's keys as drawn (`sample_rays` pass 0), which `sample_rays_sort` sorts into
    /// `keys`.
    scratch: GpuBuffer,
}

impl TrainViewBuffers {
    /// Upload `set` (the views of set `id`): its images one view at a time into one buffer.
    pub fn upload(gpu: &Gpu, id: u64, set: &SampleSet) -> Result<Self> {
        set.validate()?;
        let view_bytes = 4 * set.width as u64 * set.height as u64;
        let pixels = gpu.zeros::<u32>((set.n_pixels() as usize).max(1))?;
        for (v, img) in set.images.iter().enumerate() {
            pixels.write_at(v as u64 * view_bytes, img)?;
        }
        let f = &set.focus;
        let focus = if f.is_none() {
            gpu.zeros::<u32>(1)?
        } else {
            gpu.upload(f.pixels())?
        };
        Ok(TrainViewBuffers {
            id,
            pixels,
            cams: gpu.upload(&set.cams)?,
            focus,
            n_focus: f.pixels().len() as u32,
            focus_threshold: f.threshold(),
            focus_weights: f.weights(),
            ndc: set.ndc,
            width: set.width,
            height: set.height,
            n_pixels: set.n_pixels(),
            key_bits: set.key_bits(),
            key_draw: KeyDraw::for_device(gpu.info().kind),
            batch: None,
        })
    }

    /// The buffers of set `id` with room for a batch of `n` rays, uploading `set` into `slot`
    /// unless it holds them already (submits its own copies: call it before recording a batch).
    pub fn ensure<'a>(
        slot: &'a mut Option<TrainViewBuffers>,
        gpu: &Gpu,
        id: u64,
        set: &SampleSet,
        n: usize,
    ) -> Result<&'a mut TrainViewBuffers> {
        ensure!(
            n > 0 && n <= u32::MAX as usize,
            "a batch of {n} rays (1 to 2^32 − 1)"
        );
        if slot.as_ref().is_none_or(|v| v.id != id) {
            *slot = None; // free the old set first
            *slot = Some(TrainViewBuffers::upload(gpu, id, set)?);
        }
        let v = slot.as_mut().expect("just set");
        if v.batch.as_ref().is_none_or(|bb| bb.capacity < n) {
            let cap = n.next_power_of_two();
            v.batch = None;
            v.batch = Some(BatchBuffers {
                capacity: cap,
                rays: gpu.zeros::<f32>(6 * cap)?,
                targets: gpu.zeros::<f32>(3 * cap)?,
                keys: gpu.zeros::<u64>(cap)?,
                weights: gpu.zeros::<f32>(cap)?,
                scratch: gpu.zeros::<u64>(cap)?,
            });
        }
        Ok(v)
    }

    /// Record drawing the batch of `n` rays of `seed` from `set` (the views this set holds):
    /// `sample_rays` pass 0 and `sample_rays_sort`, or the keys from the host ([`KeyDraw`]),
    /// then `sample_rays` pass 1 ([`ensure`](Self::ensure) made room for them); returns the
    /// device addresses of its rays, targets and weights, for the kernels recorded after it.
    pub fn record_sample(
        &self,
        b: &mut Batch,
        set: &SampleSet,
        seed: u64,
        n: usize,
    ) -> Result<SampledAt> {
        let bb = self.batch.as_ref().filter(|bb| bb.capacity >= n && n > 0);
        let bb = bb.ok_or_else(|| anyhow::anyhow!("no room was made for a batch of {n} rays"))?;
        let mut push = sample_rays::Push {
            pixels: self.pixels.address(),
            cams: self.cams.address(),
            rays: bb.rays.address(),
            targets: bb.targets.address(),
            keys: bb.keys.address(),
            scratch: bb.scratch.address(),
            focus: self.focus.address(),
            weights: bb.weights.address(),
            n_focus: self.n_focus,
            focus_threshold: self.focus_threshold,
            w_focus: self.focus_weights.0,
            w_other: self.focus_weights.1,
            ndc_near: self.ndc.map_or(0.0, |p| p.near),
            ndc_sx: self.ndc.map_or(0.0, |p| p.sx),
            ndc_sy: self.ndc.map_or(0.0, |p| p.sy),
            seed,
            n_pixels: self.n_pixels,
            width: self.width,
            height: self.height,
            n_rays: n as u32,
            key_bits: self.key_bits,
            pass: 0,
        };
        match self.key_draw {
            // Draw the keys into scratch, sort them into keys per run.
            KeyDraw::Device => {
                b.dispatch_1d(&sample_rays::INFO, &push, n as u32)?;
                record_sort_runs(b, &bb.scratch, &bb.keys, n)?;
            }
            // In the command stream: an earlier step still in flight may read the keys.
            KeyDraw::Host => {
                ensure!(
                    set.n_pixels() == self.n_pixels
                        && set.key_bits() == self.key_bits
                        && set.focus.threshold() == self.focus_threshold
                        && set.focus.pixels().len() as u32 == self.n_focus,
                    "the keys of a batch drawn from other views than the ones uploaded"
                );
                let keys = sorted_keys(set, seed, n)?;
                for (i, chunk) in keys.chunks(UPDATE_KEYS).enumerate() {
                    b.update(&bb.keys, 8 * (i * UPDATE_KEYS) as u64, chunk)?;
                }
            }
        }
        // Write the rays of the sorted keys.
        push.pass = 1;
        b.dispatch_1d(&sample_rays::INFO, &push, n as u32)?;
        Ok(SampledAt {
            rays: bb.rays.address(),
            targets: bb.targets.address(),
            weights: if self.focus_threshold != 0 {
                bb.weights.address()
            } else {
                0
            },
        })
    }

    /// The last batch of `n` rays (its weights empty without a focus), once its batch has
    /// completed.
    pub fn download_batch(&self, n: usize) -> Result<SampledRays> {
        let bb = self.batch.as_ref().filter(|bb| bb.capacity >= n);
        let bb = bb.ok_or_else(|| anyhow::anyhow!("no batch of {n} rays was sampled"))?;
        Ok(SampledRays {
            keys: bb.keys.download_range(0, n)?,
            rays: bb.rays.download_range(0, 6 * n)?,
            targets: bb.targets.download_range(0, 3 * n)?,
            weights: if self.focus_threshold != 0 {
                bb.weights.download_range(0, n)?
            } else {
                Vec::new()
            },
        })
    }
}

/// Record sorting the first `n` keys of `src` into `dst` per run of [`SAMPLE_SORT_RAYS`]
/// (`sample_rays_sort`).
pub fn record_sort_runs(b: &mut Batch, src: &GpuBuffer, dst: &GpuBuffer, n: usize) -> Result<()> {
    let bytes = 8 * n as u64;
    ensure!(
        n > 0 && n <= u32::MAX as usize && src.size() >= bytes && dst.size() >= bytes,
        "sorting {n} keys from a buffer of {} bytes into one of {}",
        src.size(),
        dst.size()
    );
    let push = sample_rays_sort::Push {
        src: src.address(),
        dst: dst.address(),
        n: n as u32,
        ..Default::default()
    };
    let runs = (n as u32).div_ceil(SAMPLE_SORT_RAYS);
    b.dispatch_1d(&sample_rays_sort::INFO, &push, runs * SAMPLE_SORT_SIDE)
}

/// The rays of a training step: given on the host, or a batch to draw from training views (a
/// Vulkan backend draws it on the device, a CPU backend on the host).
#[derive(Clone, Copy)]
pub enum TrainRays<'a> {
    /// Rays (6 floats each) and targets (3 floats each) from the host, uploaded.
    Host { rays: &'a [f32], targets: &'a [f32] },
    /// The batch of `n` rays drawn with `seed` on the device from the views of set `id`.
    Sampled {
        id: u64,
        set: &'a SampleSet<'a>,
        seed: u64,
        n: usize,
    },
}

impl TrainRays<'_> {
    /// Number of rays.
    pub fn len(&self) -> usize {
        match self {
            TrainRays::Host { rays, .. } => rays.len() / 6,
            TrainRays::Sampled { n, .. } => *n,
        }
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}
