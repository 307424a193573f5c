//! Checkpoints written on a thread of their own: the training loop hands over a snapshot and
//! goes on training while it is written. One write at a time; a failed write's error comes back
//! from the next call.

use crate::run::memory;
use anyhow::{anyhow, Context, Result};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// When a training loop writes its periodic checkpoints: after every `every` steps, once at
/// least `min_seconds` have passed since the last checkpoint (or the start); never at the last
/// step, which the loop saves anyway.
pub struct Cadence {
    every: u32,
    min_gap: Duration,
    last: Instant,
}

impl Cadence {
    pub fn new(every: u32, min_seconds: f32) -> Self {
        Cadence {
            every: every.max(1),
            min_gap: Duration::from_secs_f32(min_seconds.max(0.0)),
            last: Instant::now(),
        }
    }

    /// Whether the checkpoint after step `step` (0-based) of `iters` is due now; when it is,
    /// the time since the last one starts again.
    pub fn due(&mut self, step: u32, iters: u32) -> bool {
        let done = step + 1;
        let due =
            done.is_multiple_of(self.every) && done < iters && self.last.elapsed() >= self.min_gap;
        if due {
            self.last = Instant::now();
        }
        due
    }
}

/// At most one write in progress, on its own thread.
#[derive(Default)]
pub struct BackgroundSave {
    pending: Option<JoinHandle<Result<()>>>,
}

impl BackgroundSave {
    /// Waits for the write in progress (its error, if it failed), then starts `write` on a new
    /// thread. Writes to the same file therefore land in the order they were started.
    pub fn start(&mut self, write: impl FnOnce() -> Result<()> + Send + 'static) -> Result<()> {
        self.finish()?;
        let handle = std::thread::Builder::new()
            .name("checkpoint".into())
            .spawn(write)
            .context("starting the checkpoint thread")?;
        self.pending = Some(handle);
        Ok(())
    }

    /// Writes a checkpoint of `bytes` (grid and optimiser state): after the write in progress,
    /// so that at most one copy is held besides the grid, either on the thread, from the copy
    /// `snapshot` makes, or now with `in_place` when a copy would leave less than as much again
    /// of the memory available ([`memory::room_for_copy`]).
    pub fn checkpoint<W>(
        &mut self,
        bytes: u64,
        snapshot: impl FnOnce() -> Result<W>,
        in_place: impl FnOnce() -> Result<()>,
    ) -> Result<()>
    where
        W: FnOnce() -> Result<()> + Send + 'static,
    {
        self.finish()?;
        if memory::room_for_copy(bytes) {
            self.start(snapshot()?)
        } else {
            in_place()
        }
    }

    /// Without waiting: the error of a write that has ended and failed (that write is then no
    /// longer in progress), Ok while one is still running or none failed. A loop calls it each
    /// step so that a failed write (a full disk) stops the run at once rather than at the next
    /// checkpoint.
    pub fn check(&mut self) -> Result<()> {
        if self.pending.as_ref().is_some_and(|h| h.is_finished()) {
            self.finish()
        } else {
            Ok(())
        }
    }

    /// Waits for the write in progress; its error if it failed.
    pub fn finish(&mut self) -> Result<()> {
        match self.pending.take() {
            None => Ok(()),
            Some(h) => h
                .join()
                .map_err(|_| anyhow!("the checkpoint thread panicked"))?,
        }
    }
}

impl Drop for BackgroundSave {
    /// A run that stops early (an error, a non-finite loss) still completes the checkpoint being
    /// written, so the last good one is on disk when the process exits; its error is printed.
    fn drop(&mut self) {
        if let Err(e) = self.finish() {
            eprintln!("warning: {e:#}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicU32, Ordering};
    use std::sync::Arc;
    use std::time::Duration;

    #[test]
    fn a_cadence_waits_for_its_steps_and_its_seconds() {
        let mut c = Cadence::new(5, 0.0);
        let due: Vec<u32> = (0..20).filter(|&s| c.due(s, 20)).collect();
        assert_eq!(due, vec![4, 9, 14], "every 5th step, not the last");
        // A minute between checkpoints: none in a run of milliseconds.
        let mut c = Cadence::new(5, 60.0);
        assert!((0..1000).all(|s| !c.due(s, 1000)));
        // 30 ms: the steps that come due after the gap.
        let mut c = Cadence::new(1, 0.03);
        assert!(!c.due(0, 100));
        std::thread::sleep(Duration::from_millis(40));
        assert!(c.due(1, 100), "due once the gap has passed");
        assert!(!c.due(2, 100), "and the gap starts again");
    }

    #[test]
    fn writes_run_one_at_a_time_in_order_and_errors_come_back() {
        let log = Arc::new(std::sync::Mutex::new(Vec::new()));
        let mut s = BackgroundSave::default();
        for i in 0..3 {
            let log = log.clone();
            s.start(move || {
                // The first write is the slowest: a later one must still land after it.
                std::thread::sleep(Duration::from_millis(30 - 10 * i));
                log.lock().unwrap().push(i);
                Ok(())
            })
            .unwrap();
        }
        s.finish().unwrap();
        assert_eq!(*log.lock().unwrap(), vec![0, 1, 2]);

        s.start(|| anyhow::bail!("disk full")).unwrap();
        let e = s.start(|| Ok(())).unwrap_err();
        assert!(format!("{e:#}").contains("disk full"), "{e:#}");
        s.start(|| anyhow::bail!("disk full again")).unwrap();
        assert!(format!("{:#}", s.finish().unwrap_err()).contains("again"));
        assert!(s.finish().is_ok(), "an error is returned once");
    }

    #[test]
    fn check_returns_a_failed_write_without_waiting_for_a_running_one() {
        let mut s = BackgroundSave::default();
        assert!(s.check().is_ok(), "nothing written yet");
        let (go, wait) = std::sync::mpsc::channel::<()>();
        s.start(move || {
            wait.recv().ok();
            anyhow::bail!("disk full")
        })
        .unwrap();
        assert!(s.check().is_ok(), "a write still running is not waited for");
        go.send(()).unwrap();
        let deadline = Instant::now() + Duration::from_secs(10);
        let e = loop {
            match s.check() {
                Err(e) => break e,
                Ok(()) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(1)),
                Ok(()) => panic!("the failed write was not reported"),
            }
        };
        assert!(format!("{e:#}").contains("disk full"), "{e:#}");
        assert!(s.finish().is_ok(), "an error is returned once");
    }

    #[test]
    fn dropping_waits_for_the_write_in_progress() {
        let done = Arc::new(AtomicU32::new(0));
        {
            let mut s = BackgroundSave::default();
            let d = done.clone();
            s.start(move || {
                std::thread::sleep(Duration::from_millis(50));
                d.store(1, Ordering::SeqCst);
                Ok(())
            })
            .unwrap();
        }
        assert_eq!(done.load(Ordering::SeqCst), 1);
    }
}
