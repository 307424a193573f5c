//! What a backend keeps for the training loop besides its grid, the same for both stages: the
//! background the kernels composite on and the figures of the steps not yet taken. A Vulkan
//! backend keeps them in the queue of its [`super::QueuedGrid`] (the background and the figures
//! on the device); a CPU backend in [`HostSteps`], and it draws a sampled batch on the host
//! ([`HostRays`]).

use crate::abi::buffers::Background;
use crate::abi::rays::{SampleSet, SampledRays};
use crate::abi::train::BackgroundStep;
use crate::cpu::background_spheres_step::step_spheres;
use crate::cpu::background_step::background_step;
use crate::gpu::{Phase, PhaseClock, TrainRays};
use crate::math::background_msi::BackgroundView;
use crate::math::background_msi::SphereTable;
use anyhow::{anyhow, Result};
use std::borrow::Cow;
use std::sync::Arc;

/// The background and the figures (of type `F`) of the steps a backend has not handed out.
pub trait StepStore<F> {
    /// The kind of backend ("vulkan" or "cpu").
    fn kind(&self) -> &'static str;
    /// The figures of every step since the last call, in order (waits for the steps running).
    fn take(&mut self) -> Result<Vec<F>>;
    /// The figures of the step submitted last, waited for; those of earlier steps stay.
    fn last(&mut self) -> Result<F>;
    /// The background with its optimiser state.
    fn background(&self) -> Result<Background>;
    /// Replace the background (colour, whether it is learned, its optimiser state).
    fn set_background(&mut self, bg: Background) -> Result<()>;
    /// The background's spheres with their optimiser state (`None`: the colour alone).
    fn spheres(&self) -> Result<Option<SphereTable>>;
    /// Replace them (learned when their shape says so).
    fn set_spheres(&mut self, spheres: Option<SphereTable>) -> Result<()>;
}

/// A CPU backend's background and the figures of its steps not yet taken.
pub struct HostSteps<F> {
    pub bg: Background,
    /// The background's spheres, and their gradient of the step so far.
    pub spheres: Option<Arc<SphereTable>>,
    pub sphere_grad: Vec<f32>,
    done: Vec<F>,
}

impl<F> Default for HostSteps<F> {
    /// A white, fixed background and no figures.
    fn default() -> Self {
        HostSteps {
            bg: Background::new([1.0; 3], false),
            spheres: None,
            sphere_grad: Vec::new(),
            done: Vec::new(),
        }
    }
}

impl<F> HostSteps<F> {
    /// Keep the figures of a step until they are taken.
    pub fn push(&mut self, figures: F) {
        self.done.push(figures);
    }

    /// The background as the twins read it.
    pub fn view(&self) -> BackgroundView<'_> {
        BackgroundView::new(self.bg.rgb, self.spheres.as_deref())
    }

    /// The background's gradients a training pass adds to: the colour's when it is learned,
    /// the spheres' when they are, and the background as the pass reads it.
    pub fn train_grads(
        &mut self,
    ) -> (
        BackgroundView<'_>,
        Option<&mut [f32; 3]>,
        Option<&mut [f32]>,
    ) {
        let HostSteps {
            bg,
            spheres,
            sphere_grad,
            ..
        } = self;
        let learned = spheres.as_ref().is_some_and(|s| s.learned());
        let view = BackgroundView::new(bg.rgb, spheres.as_deref());
        (
            view,
            bg.learned().then_some(&mut bg.grad),
            learned.then_some(&mut sphere_grad[..]),
        )
    }

    /// The background step: the colour's (twin of `background_step`) and, when they are
    /// learned, the spheres' (their TV, then the twin of `background_spheres_step`).
    pub fn step_background(&mut self, s: &BackgroundStep) {
        background_step(&mut self.bg, s.lr, s.beta, s.eps);
        if let Some(sp) = self.spheres.as_mut().filter(|sp| sp.learned()) {
            step_spheres(Arc::make_mut(sp), &mut self.sphere_grad, s);
        }
    }
}

impl<F> StepStore<F> for HostSteps<F> {
    fn kind(&self) -> &'static str {
        "cpu"
    }

    fn take(&mut self) -> Result<Vec<F>> {
        Ok(std::mem::take(&mut self.done))
    }

    fn last(&mut self) -> Result<F> {
        let last = self.done.pop();
        last.ok_or_else(|| anyhow!("a submitted step left no figures"))
    }

    fn background(&self) -> Result<Background> {
        Ok(self.bg)
    }

    fn set_background(&mut self, bg: Background) -> Result<()> {
        self.bg = bg;
        Ok(())
    }

    fn spheres(&self) -> Result<Option<SphereTable>> {
        Ok(self.spheres.as_deref().cloned())
    }

    fn set_spheres(&mut self, spheres: Option<SphereTable>) -> Result<()> {
        self.sphere_grad = vec![0.0; spheres.as_ref().map_or(0, |s| s.table.len())];
        self.spheres = spheres.map(Arc::new);
        Ok(())
    }
}

/// The rays of a training step on the host: borrowed from the caller, or drawn from the views.
pub struct HostRays<'a> {
    /// 6 floats per ray.
    pub rays: Cow<'a, [f32]>,
    /// 3 floats per ray.
    pub targets: Cow<'a, [f32]>,
    /// Per-ray importance weights (`None`: every weight 1).
    pub weights: Option<Vec<f32>>,
}

impl<'a> HostRays<'a> {
    /// `src`'s rays: as given, or drawn by `draw` (the CPU backends': the `sample_rays` twin;
    /// its time charged to `clock`'s sampling).
    pub fn of(
        src: TrainRays<'a>,
        clock: &mut PhaseClock,
        draw: impl FnOnce(&SampleSet, u64, usize) -> Result<SampledRays>,
    ) -> Result<Self> {
        Ok(match src {
            TrainRays::Host { rays, targets } => HostRays {
                rays: rays.into(),
                targets: targets.into(),
                weights: None,
            },
            TrainRays::Sampled { set, seed, n, .. } => {
                let batch = draw(set, seed, n)?;
                clock.mark(Phase::Sampling);
                HostRays {
                    rays: batch.rays.into(),
                    targets: batch.targets.into(),
                    weights: (!batch.weights.is_empty()).then_some(batch.weights),
                }
            }
        })
    }
}
