//! A stop asked for from outside while a training loop runs (Ctrl-C, `kill`, a job scheduler's
//! SIGTERM): the first SIGINT or SIGTERM asks the loop to write a checkpoint after the step it is
//! on and return [`Interrupted`]; a second one ends the process at once, as it would without the
//! handler. Outside a training loop (no [`Catch`] alive) both signals keep their usual effect, so
//! a command that is extracting or evaluating stops at once.

use anyhow::{Error, Result};
use std::fmt;
use std::path::PathBuf;
use std::sync::atomic::{AtomicI32, Ordering};

/// The signal that asked for a stop; 0 while none has.
static REQUESTED: AtomicI32 = AtomicI32::new(0);

#[cfg(unix)]
const SIGNALS: [libc::c_int; 2] = [libc::SIGINT, libc::SIGTERM];

/// The handler: records the signal and gives both signals back their default action, so that a
/// second one ends the process. Only async-signal-safe calls (an atomic store, `signal`).
#[cfg(unix)]
extern "C" fn on_signal(sig: libc::c_int) {
    REQUESTED.store(sig, Ordering::SeqCst);
    for s in SIGNALS {
        // SAFETY: `signal` with SIG_DFL is async-signal-safe.
        unsafe {
            libc::signal(s, libc::SIG_DFL);
        }
    }
}

/// While alive, SIGINT and SIGTERM ask for a stop ([`requested`]) instead of ending the process;
/// dropped, the dispositions it replaced come back.
pub struct Catch {
    #[cfg(unix)]
    previous: Vec<(libc::c_int, libc::sigaction)>,
}

/// Catch SIGINT and SIGTERM until the returned guard is dropped.
pub fn catch() -> Catch {
    #[cfg(unix)]
    {
        let mut previous = Vec::new();
        for sig in SIGNALS {
            // SAFETY: a zeroed sigaction is a valid value (no flags, empty mask) and `on_signal`
            // only does async-signal-safe work; the old action is kept to be restored.
            unsafe {
                let mut action: libc::sigaction = std::mem::zeroed();
                action.sa_sigaction = on_signal as extern "C" fn(libc::c_int) as usize;
                libc::sigemptyset(&mut action.sa_mask);
                let mut old: libc::sigaction = std::mem::zeroed();
                if libc::sigaction(sig, &action, &mut old) == 0 {
                    previous.push((sig, old));
                }
            }
        }
        Catch { previous }
    }
    #[cfg(not(unix))]
    Catch {}
}

impl Drop for Catch {
    fn drop(&mut self) {
        #[cfg(unix)]
        for (sig, old) in &self.previous {
            // SAFETY: restores an action `sigaction` returned.
            unsafe {
                libc::sigaction(*sig, old, std::ptr::null_mut());
            }
        }
    }
}

/// The signal that asked for a stop, if one has (it stays asked for until the process ends, so
/// a command that trains twice stops at the second training's first step too).
pub fn requested() -> Option<i32> {
    match REQUESTED.load(Ordering::SeqCst) {
        0 => None,
        s => Some(s),
    }
}

/// A training run stopped by a signal after writing its checkpoint.
#[derive(Debug)]
pub struct Interrupted {
    /// The signal (SIGINT 2, SIGTERM 15).
    pub signal: i32,
    /// Steps done (the checkpoint's step).
    pub done: u32,
    pub iters: u32,
    pub checkpoint: PathBuf,
}

impl fmt::Display for Interrupted {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(
            f,
            "stopped by signal {} after step {} of {}; the checkpoint {} holds that step \
             (`train --resume` goes on from it)",
            self.signal,
            self.done,
            self.iters,
            self.checkpoint.display()
        )
    }
}

impl std::error::Error for Interrupted {}

impl Interrupted {
    /// The error that ends a run `signal` stopped after `done` of `iters` steps, once the
    /// checkpoint written to `checkpoint` is on disk (`written`: that write's outcome; its own
    /// error if it failed).
    pub fn after_checkpoint(
        signal: i32,
        done: u32,
        iters: u32,
        checkpoint: PathBuf,
        written: Result<()>,
    ) -> Error {
        match written {
            Err(e) => e,
            Ok(()) => Error::new(Interrupted {
                signal,
                done,
                iters,
                checkpoint,
            }),
        }
    }
}

/// The [`Interrupted`] that `e` holds, if any (under any context).
pub fn cause(e: &Error) -> Option<&Interrupted> {
    e.chain().find_map(|c| c.downcast_ref::<Interrupted>())
}

/// `r` for a caller that records a failed training and goes on (the benches, `demo`), unless a
/// signal stopped it: that error ends the caller too (`?` passes it on).
pub fn unless_stopped<T>(r: Result<T, Error>) -> Result<Result<T, Error>, Error> {
    match r {
        Err(e) if cause(&e).is_some() => Err(e),
        r => Ok(r),
    }
}

/// The exit code of a command stopped by `signal`: 128 + the signal, as shells report it.
pub fn exit_code(i: &Interrupted) -> u8 {
    u8::try_from(128 + i.signal).unwrap_or(1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_interrupted_run_is_found_under_context_and_named_in_the_message() {
        let e = Error::new(Interrupted {
            signal: 2,
            done: 40,
            iters: 100,
            checkpoint: PathBuf::from("run/plenoxels.npz"),
        })
        .context("stage 1");
        let i = cause(&e).expect("found under the context");
        assert_eq!((i.done, exit_code(i)), (40, 130));
        let text = format!("{e:#}");
        assert!(text.contains("after step 40 of 100"), "{text}");
        assert!(text.contains("run/plenoxels.npz") && text.contains("--resume"));
        assert!(cause(&anyhow::anyhow!("disk full")).is_none());
        // A failure goes back to the caller to record; the stop ends it.
        assert!(matches!(
            unless_stopped::<()>(Err(anyhow::anyhow!("disk full"))),
            Ok(Err(_))
        ));
        assert!(unless_stopped::<()>(Err(e)).is_err());
    }
}
