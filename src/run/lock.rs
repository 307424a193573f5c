//! The lock that keeps a second writer out of a run directory: a file created exclusively
//! (`create_new`) holding the writer's process id and host name, removed when the writer ends.
//! A lock left by a process that was killed is taken over when its process is gone from this
//! host; a lock from another host is never taken over (its process cannot be checked from here).
//! A lock that could not be written (a full disk) is removed at once; an empty one older than
//! [`EMPTY_LOCK_GRACE`] (left by a process killed between creating and writing it) is taken over.

use anyhow::{bail, Context, Result};
use std::fs;
use std::io::{ErrorKind, Write};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// How long an empty lock file may be another process's lock in the making.
pub const EMPTY_LOCK_GRACE: Duration = Duration::from_secs(5);

/// Who holds a lock: `pid host`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Holder {
    pub pid: u32,
    pub host: String,
}

impl Holder {
    /// This process on this host.
    pub fn me() -> Holder {
        Holder {
            pid: std::process::id(),
            host: host_name(),
        }
    }

    fn parse(text: &str) -> Option<Holder> {
        let mut parts = text.split_whitespace();
        let pid = parts.next()?.parse().ok()?;
        let host = parts.next()?.to_string();
        Some(Holder { pid, host })
    }

    fn line(&self) -> String {
        format!("{} {}\n", self.pid, self.host)
    }

    /// Whether this holder's process is known to be gone: it ran on this host and no process
    /// has its id (Linux `/proc`; elsewhere a holder is never presumed gone).
    fn is_gone(&self) -> bool {
        self.host == host_name()
            && Path::new("/proc/self").exists()
            && !Path::new(&format!("/proc/{}", self.pid)).exists()
    }
}

/// This machine's host name (`/proc/sys/kernel/hostname`, else `$HOSTNAME`, else "localhost").
pub fn host_name() -> String {
    fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .or_else(|| std::env::var("HOSTNAME").ok())
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty() && !s.contains(char::is_whitespace))
        .unwrap_or_else(|| "localhost".into())
}

/// Whether `path` was last modified more than `age` ago (unknown: no).
fn is_older_than(path: &Path, age: Duration) -> bool {
    fs::metadata(path)
        .and_then(|m| m.modified())
        .ok()
        .and_then(|t| t.elapsed().ok())
        .is_some_and(|e| e > age)
}

/// A held lock; dropping it removes the lock file (if it still names this process).
#[derive(Debug)]
pub struct Lock {
    path: PathBuf,
    me: Holder,
}

impl Lock {
    /// Take the lock file `path` for this process. Refused while another live process holds it.
    pub fn acquire(path: &Path) -> Result<Lock> {
        let me = Holder::me();
        // Two tries: the second after removing a lock whose holder is gone.
        for _ in 0..2 {
            match fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(path)
            {
                Ok(mut f) => {
                    if let Err(e) = f.write_all(me.line().as_bytes()).and_then(|_| f.sync_all()) {
                        // An empty lock would keep every later writer out.
                        let _ = fs::remove_file(path);
                        return Err(e).with_context(|| format!("writing lock {}", path.display()));
                    }
                    return Ok(Lock {
                        path: path.to_path_buf(),
                        me,
                    });
                }
                Err(e) if e.kind() == ErrorKind::AlreadyExists => {
                    let text = fs::read_to_string(path).unwrap_or_default();
                    match Holder::parse(&text) {
                        Some(h) if h == me => bail!(
                            "{} is already locked by this process",
                            path.parent().unwrap_or(path).display()
                        ),
                        Some(h) if h.is_gone() => {
                            eprintln!(
                                "taking over the lock {} left by process {} (no longer running)",
                                path.display(),
                                h.pid
                            );
                            fs::remove_file(path).with_context(|| {
                                format!("removing stale lock {}", path.display())
                            })?;
                        }
                        Some(h) => bail!(
                            "{} is in use by process {} on host {} (lock {}); wait for it to \
                             finish, or remove the lock if that process is gone",
                            path.parent().unwrap_or(path).display(),
                            h.pid,
                            h.host,
                            path.display()
                        ),
                        None if text.is_empty() && is_older_than(path, EMPTY_LOCK_GRACE) => {
                            eprintln!(
                                "taking over the empty lock {} (left by a process stopped while \
                                 taking it)",
                                path.display()
                            );
                            fs::remove_file(path).with_context(|| {
                                format!("removing stale lock {}", path.display())
                            })?;
                        }
                        None => bail!(
                            "{}: unreadable lock file {:?}; if no other alphasurf process writes \
                             there, remove it (rm {}) and run the command again",
                            path.display(),
                            text,
                            path.display()
                        ),
                    }
                }
                Err(e) => {
                    return Err(e).with_context(|| format!("creating lock {}", path.display()))
                }
            }
        }
        bail!("{}: could not take the lock", path.display())
    }

    /// The lock file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The same lock after its file was moved to `path` (with the folder holding it).
    pub fn moved_to(mut self, path: PathBuf) -> Lock {
        self.path = path;
        self
    }
}

impl Drop for Lock {
    fn drop(&mut self) {
        let ours = fs::read_to_string(&self.path)
            .ok()
            .and_then(|t| Holder::parse(&t))
            .is_some_and(|h| h == self.me);
        if ours {
            let _ = fs::remove_file(&self.path);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_live_holder_keeps_others_out_and_a_dead_one_is_taken_over() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("run.lock");
        let lock = Lock::acquire(&path).unwrap();
        assert!(Lock::acquire(&path).is_err(), "same process, second writer");
        drop(lock);
        assert!(!path.exists(), "the lock is released on drop");
        // A live process (pid 1 exists on Linux) on this host.
        fs::write(&path, format!("1 {}\n", host_name())).unwrap();
        let err = format!("{:#}", Lock::acquire(&path).unwrap_err());
        assert!(err.contains("in use by process 1"), "{err}");
        // Another host: never taken over.
        fs::write(&path, "4000000000 some-other-host\n").unwrap();
        assert!(Lock::acquire(&path).is_err());
        // A process that is gone on this host (pids never reach 4e9 on Linux).
        fs::write(&path, format!("4000000000 {}\n", host_name())).unwrap();
        let lock = Lock::acquire(&path).unwrap();
        assert_eq!(
            Holder::parse(&fs::read_to_string(&path).unwrap()),
            Some(Holder::me())
        );
        drop(lock);
        // An empty lock: another process's in the making while fresh, a leftover once old.
        fs::write(&path, "").unwrap();
        let err = format!("{:#}", Lock::acquire(&path).unwrap_err());
        assert!(
            err.contains("unreadable lock") && err.contains("rm "),
            "{err}"
        );
        let old = std::time::SystemTime::now() - 2 * EMPTY_LOCK_GRACE;
        fs::File::options()
            .write(true)
            .open(&path)
            .unwrap()
            .set_modified(old)
            .unwrap();
        drop(Lock::acquire(&path).unwrap());
        assert!(!path.exists());
    }
}
