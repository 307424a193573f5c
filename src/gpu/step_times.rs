//! Where the wall time of a training step goes on the host: [`StepTimes`], milliseconds per phase,
//! measured by a [`PhaseClock`] whose spans are contiguous, so the phases of a step add up to the
//! time between the clock's start and its last mark; with the device time of its kernels, a
//! step's [`StepTiming`].

use std::time::Instant;

/// A phase of a training step (a field of [`StepTimes`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    Sampling,
    Upload,
    Record,
    Submit,
    Wait,
    Readback,
    Compute,
    Bookkeeping,
    Other,
}

/// Host wall time of a training step (or of several, summed) per phase, in milliseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct StepTimes {
    /// Drawing the ray batch on the host (views, pixels, the view/Z-order sort) and flattening it;
    /// for a batch drawn on a Vulkan device, recording the draw (with the keys drawn on the host
    /// on a CPU device, `gpu::KeyDraw`).
    pub sampling: f64,
    /// Writing rays, targets and step parameters into device buffers (through a staging buffer
    /// and its own submission where device memory is not host-visible).
    pub upload: f64,
    /// Creating the command buffer (pool, timestamp queries) and recording the step into it.
    pub record: f64,
    /// Handing the command buffer to the queue (fence, `vkQueueSubmit`).
    pub submit: f64,
    /// Waiting on the fence; the device runs the step's kernels meanwhile.
    pub wait: f64,
    /// Reading back timestamps, per-ray losses and counters, and reducing them to the step's
    /// figures (MSE, regulariser losses).
    pub readback: f64,
    /// The CPU twin's kernels, which run on the host (0 on the Vulkan backend, whose kernels run
    /// during `wait`).
    pub compute: f64,
    /// The loop's own work around the step: schedule (learning rates, regulariser chunks),
    /// loss/PSNR and counter totals.
    pub bookkeeping: f64,
    /// Wall time in no named phase (calls between the spans); set by whoever measured the wall.
    pub other: f64,
}

/// Where a training step's time went: its kernels on the device and its phases on the host.
#[derive(Clone, Copy, Debug, Default)]
pub struct StepTiming {
    /// Device time of the step's kernels in ns (0 on the CPU backend).
    pub device_ns: f64,
    /// Host time of the step by phase (upload to readback on Vulkan, compute on the CPU).
    pub host: StepTimes,
}

impl Phase {
    /// Every phase, in the order of [`StepTimes`]' fields.
    pub const ALL: [Phase; 9] = [
        Phase::Sampling,
        Phase::Upload,
        Phase::Record,
        Phase::Submit,
        Phase::Wait,
        Phase::Readback,
        Phase::Compute,
        Phase::Bookkeeping,
        Phase::Other,
    ];

    /// The name of its field (and JSON key).
    pub fn name(self) -> &'static str {
        match self {
            Phase::Sampling => "sampling",
            Phase::Upload => "upload",
            Phase::Record => "record",
            Phase::Submit => "submit",
            Phase::Wait => "wait",
            Phase::Readback => "readback",
            Phase::Compute => "compute",
            Phase::Bookkeeping => "bookkeeping",
            Phase::Other => "other",
        }
    }
}

impl StepTimes {
    /// (name, ms) of every phase, in the order of the fields.
    pub fn phases(&self) -> [(&'static str, f64); 9] {
        Phase::ALL.map(|p| (p.name(), self.get(p)))
    }

    /// Sum over the phases.
    pub fn total(&self) -> f64 {
        Phase::ALL.iter().map(|&p| self.get(p)).sum()
    }

    /// The time of `phase`.
    pub fn get(mut self, phase: Phase) -> f64 {
        *self.get_mut(phase)
    }

    /// The field of `phase`.
    pub fn get_mut(&mut self, phase: Phase) -> &mut f64 {
        match phase {
            Phase::Sampling => &mut self.sampling,
            Phase::Upload => &mut self.upload,
            Phase::Record => &mut self.record,
            Phase::Submit => &mut self.submit,
            Phase::Wait => &mut self.wait,
            Phase::Readback => &mut self.readback,
            Phase::Compute => &mut self.compute,
            Phase::Bookkeeping => &mut self.bookkeeping,
            Phase::Other => &mut self.other,
        }
    }

    /// Adds `o` phase by phase.
    pub fn add(&mut self, o: &StepTimes) {
        for p in Phase::ALL {
            *self.get_mut(p) += o.get(p);
        }
    }

    /// Every phase times `k` (e.g. 1/steps for a mean per step).
    pub fn scaled(mut self, k: f64) -> StepTimes {
        for p in Phase::ALL {
            *self.get_mut(p) *= k;
        }
        self
    }
}

/// A stopwatch charged in contiguous spans: each [`mark`](Self::mark) adds the time since the
/// previous mark (or the start) to one phase of `times`.
#[derive(Debug)]
pub struct PhaseClock {
    since: Instant,
    pub times: StepTimes,
}

impl PhaseClock {
    pub fn start() -> Self {
        PhaseClock {
            since: Instant::now(),
            times: StepTimes::default(),
        }
    }

    /// Charges the time since the last mark to `phase`.
    pub fn mark(&mut self, phase: Phase) {
        let now = Instant::now();
        *self.times.get_mut(phase) += (now - self.since).as_secs_f64() * 1e3;
        self.since = now;
    }

    /// Takes the phases a callee measured over the span since the last mark (`inner`) in place of
    /// that span; what the callee left unmeasured goes to `other`.
    pub fn absorb(&mut self, inner: &StepTimes) {
        let now = Instant::now();
        let span = (now - self.since).as_secs_f64() * 1e3;
        self.times.add(inner);
        self.times.other += (span - inner.total()).max(0.0);
        self.since = now;
    }
}

/// `f()`, with the host time it took charged to `phase`.
pub fn timed<T>(
    phase: Phase,
    f: impl FnOnce() -> anyhow::Result<T>,
) -> anyhow::Result<(T, StepTimes)> {
    let mut clock = PhaseClock::start();
    let v = f()?;
    clock.mark(phase);
    Ok((v, clock.times))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn marks_cover_the_clock_and_absorb_keeps_the_total() {
        let t0 = Instant::now();
        let mut c = PhaseClock::start();
        std::thread::sleep(std::time::Duration::from_millis(3));
        c.mark(Phase::Sampling);
        let mut inner = PhaseClock::start();
        std::thread::sleep(std::time::Duration::from_millis(2));
        inner.mark(Phase::Wait);
        std::thread::sleep(std::time::Duration::from_millis(1));
        c.absorb(&inner.times);
        let wall = t0.elapsed().as_secs_f64() * 1e3;
        let t = c.times;
        assert!(
            t.sampling >= 3.0 && t.wait >= 2.0 && t.other >= 1.0,
            "{t:?}"
        );
        assert!(
            t.total() <= wall && t.total() >= 0.9 * wall,
            "{t:?} vs {wall}"
        );
        let mut sum = t;
        sum.add(&t);
        assert_eq!(sum.scaled(0.5), t);
        let keys: Vec<String> = serde_json::to_value(t)
            .unwrap()
            .as_object()
            .unwrap()
            .keys()
            .cloned()
            .collect();
        let mut names = Phase::ALL.map(|p| p.name().to_string()).to_vec();
        names.sort();
        assert_eq!(keys, names, "the JSON keys are the phases' names");
    }
}
