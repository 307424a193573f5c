//! The training progress bar: step, loss, PSNR (smoothed), rays/s after the warm-up, ETA. Hidden
//! when stderr is not a terminal or progress is off; a summary line is logged every 10 % then.
//! With it, the training throughput both stages count the same way ([`Throughput`]).

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::time::Instant;

/// Progress of a training stage.
pub struct Progress {
    bar: ProgressBar,
    total: u64,
    /// Whether the user wants progress at all (bar on a terminal, else a line every 10 %).
    visible: bool,
    ema_mse: Option<f64>,
    next_log: u64,
}

impl Progress {
    pub fn new(total: u64, start: u64, show: bool) -> Self {
        let bar = if show && console_is_terminal() {
            ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr())
        } else {
            ProgressBar::hidden()
        };
        bar.set_style(
            ProgressStyle::with_template(
                "{bar:30.cyan/blue} step {pos}/{len} {msg} elapsed {elapsed} ETA {eta}",
            )
            .expect("valid template"),
        );
        bar.set_position(start);
        Progress {
            bar,
            total,
            visible: show,
            ema_mse: None,
            next_log: start + total / 10,
        }
    }

    /// Report step `pos` (1-based) with its batch MSE and the training throughput so far.
    pub fn step(&mut self, pos: u64, mse: f64, rays_per_s: Option<f64>) {
        let ema = self.ema_mse.map_or(mse, |e| 0.95 * e + 0.05 * mse);
        self.ema_mse = Some(ema);
        let rate = rays_per_s.map_or("warming up".to_string(), |r| {
            format!("{:.0}k rays/s", r / 1e3)
        });
        let msg = format!("loss {mse:.5} PSNR {:.2} dB {rate}", -10.0 * ema.log10());
        self.bar.set_position(pos);
        self.bar.set_message(msg.clone());
        if self.visible && self.bar.is_hidden() && (pos >= self.next_log || pos == self.total) {
            eprintln!("step {pos}/{} {msg}", self.total);
            self.next_log = pos + (self.total / 10).max(1);
        }
    }

    /// A one-off line (e.g. "upsampling").
    pub fn message(&self, text: &str) {
        if !self.visible {
            return;
        }
        if self.bar.is_hidden() {
            eprintln!("{text}");
        } else {
            self.bar.println(text);
        }
    }

    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

/// Training throughput: the rays of every step this process trained, and the rays and seconds of
/// those after its first 10 (warm-up: pipeline compiles).
pub struct Throughput {
    start_step: u32,
    rays: u64,
    secs: f64,
    timed_rays: u64,
    timed_secs: f64,
}

impl Throughput {
    /// Counting from step `start_step` (0, or the step after a resumed checkpoint).
    pub fn new(start_step: u32) -> Self {
        Throughput {
            start_step,
            rays: 0,
            secs: 0.0,
            timed_rays: 0,
            timed_secs: 0.0,
        }
    }

    /// Step `step` trained `rays` rays in `secs` seconds.
    pub fn add(&mut self, step: u32, rays: usize, secs: f64) {
        if step >= self.start_step + 10 {
            self.timed_rays += rays as u64;
            self.timed_secs += secs;
        }
        self.rays += rays as u64;
        self.secs += secs;
    }

    /// Rays per second over the steps after the warm-up, once there are any.
    pub fn rays_per_s(&self) -> Option<f64> {
        (self.timed_secs > 0.0).then(|| self.timed_rays as f64 / self.timed_secs)
    }

    /// The run's figure: rays per second after the warm-up, or, for a run no longer than the
    /// warm-up, over all its steps (compiles included; a short run still has a figure).
    pub fn run_rays_per_s(&self) -> f64 {
        self.rays_per_s().unwrap_or(if self.secs > 0.0 {
            self.rays as f64 / self.secs
        } else {
            0.0
        })
    }

    /// Rays of every step so far.
    pub fn rays(&self) -> u64 {
        self.rays
    }
}

fn console_is_terminal() -> bool {
    use std::io::IsTerminal;
    std::io::stderr().is_terminal()
}

/// Steps between reads of the training figures (loss, counters): the backends keep them on the
/// device meanwhile, so a step never waits for the host to read them. At most
/// `gpu::STEP_SLOTS`.
pub const READ_EVERY: u32 = 16;

/// The steps submitted since the figures were last read, and the wall time they took: a group
/// of at most [`READ_EVERY`] steps, read together at the end of the run, before a checkpoint
/// or an upsampling, and every `READ_EVERY` steps.
pub struct StepGroup {
    steps: Vec<u32>,
    since: Instant,
}

impl Default for StepGroup {
    fn default() -> Self {
        StepGroup {
            steps: Vec::new(),
            since: Instant::now(),
        }
    }
}

impl StepGroup {
    /// Step `step` was submitted.
    pub fn push(&mut self, step: u32) {
        self.steps.push(step);
    }

    /// Whether the figures are to be read after step `step` of `iters` (`checkpoint`: one is
    /// written after it).
    pub fn due(&self, step: u32, iters: u32, checkpoint: bool) -> bool {
        checkpoint || step + 1 == iters || self.steps.len() >= READ_EVERY as usize
    }

    /// The group's steps and their wall seconds since the group started; a new group starts now.
    pub fn take(&mut self) -> (Vec<u32>, f64) {
        let secs = self.since.elapsed().as_secs_f64();
        self.since = Instant::now();
        (std::mem::take(&mut self.steps), secs)
    }

    /// Start the group's clock again (after work that is not training: a checkpoint, an
    /// upsampling), once its steps have been read.
    pub fn restart(&mut self) {
        self.since = Instant::now();
    }
}

/// Pair a group's steps with the figures a backend returned for them.
pub fn pair<S>(steps: Vec<u32>, stats: Vec<S>) -> anyhow::Result<Vec<(u32, S)>> {
    anyhow::ensure!(
        steps.len() == stats.len(),
        "the backend returned the figures of {} steps for {} submitted",
        stats.len(),
        steps.len()
    );
    Ok(steps.into_iter().zip(stats).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_within_the_warm_up_still_has_a_rate() {
        let mut t = Throughput::new(0);
        assert_eq!(t.run_rays_per_s(), 0.0);
        for s in 0..5 {
            t.add(s, 100, 0.5);
        }
        assert_eq!(t.rays_per_s(), None, "still warming up");
        assert_eq!(t.run_rays_per_s(), 200.0);
        for s in 5..20 {
            t.add(s, 100, 0.1);
        }
        let rate = t.run_rays_per_s();
        assert!(
            (rate - 1000.0).abs() < 1e-6,
            "after the warm-up, its steps only: {rate}"
        );
    }
}
