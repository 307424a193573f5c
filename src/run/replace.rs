//! Writing a whole folder a user owns (`make-scene`'s dataset, `import`'s run): the new content is
//! built in a staging folder beside it (`.NAME.partial`) and swapped in only when complete, so a
//! failure, a full disk or a kill leaves the previous folder whole. Entries of the previous folder
//! that the writer does not own (the user's own files) are moved into the new one.
//!
//! The swap is one atomic exchange of the two folders where the system has it (Linux
//! `renameat2(RENAME_EXCHANGE)`), else two renames. A staging folder left by a killed writer is
//! recognised by its name and cleared by the next writer, unless it holds files that are not the
//! writer's (then it is named, with what to do).

use super::files::LOCK;
use super::lock::Lock;
use anyhow::{bail, Context, Result};
use std::fs;
use std::path::{Path, PathBuf};

/// A folder being rebuilt beside its target; dropped before [`Replacement::commit`], the staging
/// folder is removed and the target is untouched.
#[derive(Debug)]
pub struct Replacement {
    target: PathBuf,
    staging: PathBuf,
    /// Which entry names (directly in the folder) the writer owns.
    owned: fn(&str) -> bool,
    lock: Option<Lock>,
}

/// The staging folder of `target`: `.NAME.partial` beside it.
pub fn staging_path(target: &Path) -> Result<PathBuf> {
    let name = target
        .file_name()
        .with_context(|| format!("{} has no folder name", target.display()))?;
    let mut staged = std::ffi::OsString::from(".");
    staged.push(name);
    staged.push(".partial");
    Ok(target.with_file_name(staged))
}

/// The entries of `dir` that `owned` does not claim (the lock and temporaries aside).
fn foreign_entries(dir: &Path, owned: fn(&str) -> bool) -> Result<Vec<String>> {
    let mut names = Vec::new();
    for e in fs::read_dir(dir).with_context(|| format!("reading {}", dir.display()))? {
        let name = e?.file_name().to_string_lossy().into_owned();
        let base = name.strip_suffix(".tmp").unwrap_or(&name);
        if name != LOCK && !owned(base) {
            names.push(name);
        }
    }
    names.sort();
    Ok(names)
}

impl Replacement {
    /// Start rebuilding `target`: create (or take over and clear) its staging folder and lock it.
    /// `owned` names the entries the writer writes; a leftover staging folder holding anything
    /// else is refused, naming it.
    pub fn begin(target: &Path, owned: fn(&str) -> bool) -> Result<Replacement> {
        // A link to a folder: the folder is what is replaced (the swap would move the link).
        let resolved;
        let target = if target.is_symlink() {
            resolved = fs::canonicalize(target)
                .with_context(|| format!("resolving the link {}", target.display()))?;
            resolved.as_path()
        } else {
            target
        };
        let staging = staging_path(target)?;
        if staging.exists() {
            let lock = Lock::acquire(&staging.join(LOCK)).with_context(|| {
                format!(
                    "{} is being rebuilt by another process (its staging folder {} is locked)",
                    target.display(),
                    staging.display()
                )
            })?;
            let foreign = foreign_entries(&staging, owned)?;
            if !foreign.is_empty() {
                bail!(
                    "{} was left by an interrupted replacement of {} and holds files that are not \
                     its own ({}): move them where they belong, then remove it (rm -r {})",
                    staging.display(),
                    target.display(),
                    foreign.join(", "),
                    staging.display()
                );
            }
            eprintln!(
                "removing {} (left by an interrupted write of {})",
                staging.display(),
                target.display()
            );
            drop(lock);
            fs::remove_dir_all(&staging)
                .with_context(|| format!("removing {}", staging.display()))?;
        }
        fs::create_dir_all(&staging)
            .with_context(|| format!("creating staging folder {}", staging.display()))?;
        let lock = Lock::acquire(&staging.join(LOCK))?;
        Ok(Replacement {
            target: target.to_path_buf(),
            staging,
            owned,
            lock: Some(lock),
        })
    }

    /// The folder to write the new content into.
    pub fn path(&self) -> &Path {
        &self.staging
    }

    /// Swap the complete new content in: the target gets it, plus the entries of the previous
    /// target that are not the writer's; the rest of the previous content is removed.
    pub fn commit(mut self) -> Result<()> {
        let (target, staging) = (self.target.clone(), self.staging.clone());
        sync_dir(&staging)?;
        if !target.exists() {
            fs::rename(&staging, &target).with_context(|| {
                format!("cannot move {} to {}", staging.display(), target.display())
            })?;
        } else {
            exchange(&staging, &target)?;
            // The staging path now holds the previous content: the user's entries move across
            // (if a move fails they stay there, and the next writer names the folder).
            let lock = self.lock.take();
            for name in foreign_entries(&staging, self.owned)? {
                let (from, to) = (staging.join(&name), target.join(&name));
                if to.exists() {
                    bail!(
                        "{} is in both the previous and the new {}; the previous one was kept in \
                         {}",
                        name,
                        target.display(),
                        staging.display()
                    );
                }
                fs::rename(&from, &to)
                    .with_context(|| format!("cannot move {} back", from.display()))?;
            }
            self.lock = lock;
        }
        sync_dir(target.parent().unwrap_or(Path::new(".")))?;
        // The lock came across with the new content: release it there.
        if let Some(lock) = self.lock.take() {
            drop(lock.moved_to(target.join(LOCK)));
        }
        if staging.exists() {
            fs::remove_dir_all(&staging).with_context(|| {
                format!("removing the previous content in {}", staging.display())
            })?;
        }
        Ok(())
    }
}

impl Drop for Replacement {
    fn drop(&mut self) {
        // Not committed: the partial content goes, the target was never touched.
        if self.lock.is_some() {
            let _ = fs::remove_dir_all(&self.staging);
        }
    }
}

fn sync_dir(dir: &Path) -> Result<()> {
    let dir = if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    };
    fs::File::open(dir)
        .and_then(|d| d.sync_all())
        .with_context(|| format!("syncing directory {}", dir.display()))
}

/// Swap the folders `a` and `b`: in one step where the system can, else by renaming `b` aside.
fn exchange(a: &Path, b: &Path) -> Result<()> {
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::ffi::OsStrExt;
        let c = |p: &Path| std::ffi::CString::new(p.as_os_str().as_bytes());
        let (ca, cb) = (c(a)?, c(b)?);
        // SAFETY: two NUL-terminated paths relative to the working directory; the kernel only
        // reads them. Older kernels and some file systems answer ENOSYS / EINVAL: fall back.
        let r = unsafe {
            libc::syscall(
                libc::SYS_renameat2,
                libc::AT_FDCWD,
                ca.as_ptr(),
                libc::AT_FDCWD,
                cb.as_ptr(),
                libc::RENAME_EXCHANGE,
            )
        };
        if r == 0 {
            return Ok(());
        }
        let e = std::io::Error::last_os_error();
        if !matches!(e.raw_os_error(), Some(libc::ENOSYS) | Some(libc::EINVAL)) {
            return Err(e)
                .with_context(|| format!("cannot swap {} and {}", a.display(), b.display()));
        }
    }
    // Two renames: `b` aside to a temporary beside it, `a` in, the old content to `a`.
    let aside = b.with_file_name(format!(
        "{}.previous",
        a.file_name().unwrap_or_default().to_string_lossy()
    ));
    fs::rename(b, &aside)
        .with_context(|| format!("cannot move {} aside to {}", b.display(), aside.display()))?;
    if let Err(e) = fs::rename(a, b) {
        let _ = fs::rename(&aside, b);
        return Err(e).with_context(|| format!("cannot move {} to {}", a.display(), b.display()));
    }
    fs::rename(&aside, a)
        .with_context(|| format!("cannot move {} to {}", aside.display(), a.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ours(name: &str) -> bool {
        name.starts_with("new") || name.starts_with("old")
    }

    #[test]
    fn the_target_changes_only_when_the_new_content_is_complete() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("scene");
        fs::create_dir(&target).unwrap();
        fs::write(target.join("old.png"), "old").unwrap();
        fs::write(target.join("notes.txt"), "mine").unwrap();
        // Dropped before commit: the staging folder goes, the target is as it was.
        let r = Replacement::begin(&target, ours).unwrap();
        fs::write(r.path().join("new.png"), "half").unwrap();
        let staging = r.path().to_path_buf();
        drop(r);
        assert!(!staging.exists());
        assert_eq!(fs::read_to_string(target.join("old.png")).unwrap(), "old");
        // A staging folder left by a killed writer (its lock's process gone) is cleared.
        fs::create_dir(&staging).unwrap();
        fs::write(staging.join("new.png"), "half").unwrap();
        fs::write(
            staging.join(LOCK),
            format!("4000000000 {}\n", super::super::lock::host_name()),
        )
        .unwrap();
        let r = Replacement::begin(&target, ours).unwrap();
        assert!(!r.path().join("new.png").exists());
        fs::write(r.path().join("new.png"), "new").unwrap();
        r.commit().unwrap();
        assert!(!staging.exists());
        assert_eq!(fs::read_to_string(target.join("new.png")).unwrap(), "new");
        assert!(!target.join("old.png").exists());
        assert!(!target.join(LOCK).exists());
        assert_eq!(
            fs::read_to_string(target.join("notes.txt")).unwrap(),
            "mine"
        );
        // A new target; and a leftover holding a user's file is named, not removed.
        let fresh = dir.path().join("fresh");
        let r = Replacement::begin(&fresh, ours).unwrap();
        fs::write(r.path().join("new.png"), "n").unwrap();
        r.commit().unwrap();
        assert_eq!(fs::read_to_string(fresh.join("new.png")).unwrap(), "n");
        let left = staging_path(&fresh).unwrap();
        fs::create_dir(&left).unwrap();
        fs::write(left.join("thesis.tex"), "mine").unwrap();
        let err = format!("{:#}", Replacement::begin(&fresh, ours).unwrap_err());
        assert!(err.contains("thesis.tex") && err.contains("rm -r"), "{err}");
        assert!(left.join("thesis.tex").exists());
    }
}
